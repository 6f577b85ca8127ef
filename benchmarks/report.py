"""The results table, its JSON and the README section between the suite markers."""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import time
from collections.abc import Sequence
from pathlib import Path

from .runner import VariantResult
from .servers import ROOT

__all__ = ["fmt_value", "markdown_table", "median_ratio", "save_json", "update_readme"]

BEGIN = "<!-- suite:begin -->"
END = "<!-- suite:end -->"


def fmt_value(value: float) -> str:
    """A table cell: thousands separated, else three significant digits, NaN as '-'."""
    if math.isnan(value):
        return "-"
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    return f"{value:.3g}"


def _cell(result: VariantResult, kind: str) -> str:
    stats = result.medians().get(kind, {}).get(result.variant.primary)
    if stats is None:
        return "-"
    return f"{fmt_value(stats['median'])} [{fmt_value(stats['min'])}-{fmt_value(stats['max'])}]"


def median_ratio(result: VariantResult, kind: str = "rwt", over: str = "bare") -> float:
    """The primary metric's median of ``kind`` over ``over``'s; NaN when either is missing."""
    medians = result.medians()
    primary = result.variant.primary
    try:
        top = medians[kind][primary]["median"]
        bottom = medians[over][primary]["median"]
    except KeyError:
        return float("nan")
    return top / bottom if bottom else float("nan")


def _ratio(result: VariantResult) -> str:
    ratio = median_ratio(result)
    return "-" if math.isnan(ratio) else f"{ratio:.2f}"


def _generator(result: VariantResult) -> str:
    values = [
        m["generator_cpu_pct"]
        for runs in result.runs.values()
        for m in runs
        if "generator_cpu_pct" in m
    ]
    return f"{max(values):.0f} %" if values else "-"


def _verdict(result: VariantResult) -> str:
    if result.errors and not all(result.runs.values()):
        return "FAIL (error)"
    if result.met is None:
        return "-"
    return "pass" if result.met else "MISS"


def markdown_table(results: Sequence[VariantResult]) -> str:
    """One row per variant: medians [min-max] of bare and rwt, ratio, target, verdict."""
    lines = [
        "| id | scenario | unit | bare | rwt | rwt/bare | checked | target | result"
        " | gen CPU max |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        v = r.variant
        lines.append(
            f"| {v.scenario} | {v.name} | {v.unit} | {_cell(r, 'bare')} | {_cell(r, 'rwt')} | "
            f"{_ratio(r)} | {r.shown} | {r.target} | {_verdict(r)} | {_generator(r)} |"
        )
    return "\n".join(lines)


def _commit() -> str:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=False,
        )
        return out.stdout.strip()
    except OSError:
        return "unknown"


def machine() -> dict[str, object]:
    """What the figures were measured on."""
    return {
        "cpus": os.cpu_count(),
        "load_average_1m": os.getloadavg()[0],
        "python": platform.python_version(),
        "platform": platform.platform(),
        "commit": _commit(),
        "time": time.strftime("%Y-%m-%d %H:%M:%S"),
    }


def save_json(results: Sequence[VariantResult], path: Path, options: dict[str, object]) -> None:
    """Every run's metrics, the medians and the verdicts."""
    data = {
        "machine": machine(),
        "options": options,
        "variants": [
            {
                "scenario": r.variant.scenario,
                "name": r.variant.name,
                "primary": r.variant.primary,
                "unit": r.variant.unit,
                "runs": r.runs,
                "summary": r.medians(),
                "errors": r.errors,
                "checked": r.shown,
                "target": r.target,
                "met": r.met,
            }
            for r in results
        ],
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, allow_nan=True) + "\n")


def update_readme(table: str, header: str, readme: Path) -> None:
    """Replace the text between the suite markers (added at the end if missing)."""
    text = readme.read_text() if readme.exists() else "# Benchmarks\n"
    block = f"{BEGIN}\n{header}\n\n{table}\n{END}"
    if BEGIN in text and END in text:
        before, _, rest = text.partition(BEGIN)
        _, _, after = rest.partition(END)
        text = before + block + after
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    readme.write_text(text)
