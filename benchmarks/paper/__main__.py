"""Run the paper benchmarks: ``python -m benchmarks.paper [--quick] [--only tf,png]``.

Every module of ``benchmarks.paper.MODULES`` that exists is run; the rows are
printed as one table, written to ``benchmarks/results/paper.json`` and into
``benchmarks/README.md`` between ``<!-- paper:begin -->`` and ``<!-- paper:end -->``.
``--quick`` runs tiny counts (the CI smoke test); its numbers mean nothing, so it
writes to ``benchmarks/results/quick/`` (git-ignored) instead of the tracked files.
``--only`` replaces the rows of the modules it names and keeps the other
modules' rows from the results file, when that file is of the same mode.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console
from rich.table import Table

from . import FIGURES, MODULES, ROW_KEYS, Row

HERE = Path(__file__).resolve().parent
RESULTS = HERE.parent / "results" / "paper.json"
README = HERE.parent / "README.md"
#: Where ``--quick`` writes by default (git-ignored): its numbers must not replace RESULTS.
QUICK_DIR = HERE.parent / "results" / "quick"
BEGIN, END = "<!-- paper:begin -->", "<!-- paper:end -->"


def available(only: Sequence[str] | None = None) -> list[str]:
    """The modules of ``MODULES`` (or of ``only``) that exist here."""
    names = [name for name in MODULES if only is None or name in only]
    found = []
    for name in names:
        try:
            importlib.import_module(f"{__package__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__package__}.{name}":
                raise  # the module exists but something it imports does not
            continue
        found.append(name)
    return found


def run_all(names: Sequence[str], quick: bool) -> list[Row]:
    rows: list[Row] = []
    for name in names:
        module = importlib.import_module(f"{__package__}.{name}")
        start = time.perf_counter()
        got = module.run(quick)
        for row in got:
            missing = [key for key in ROW_KEYS if key not in row]
            if missing:
                raise ValueError(f"benchmarks.paper.{name}: a row lacks {missing}: {row}")
        print(f"{name}: {len(got)} rows in {time.perf_counter() - start:.1f} s", file=sys.stderr)
        rows += got
    return rows


def fmt(value: object) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:,.1f}" if abs(value) >= 10 else f"{value:.2f}"
    return str(value)


def table(rows: list[Row], title: str) -> Table:
    out = Table(title=title)
    for key in ROW_KEYS:
        out.add_column(key, justify="right" if key in ("paper", "ours") else "left")
    for row in rows:
        out.add_row(*(fmt(row[key]) for key in ROW_KEYS))
    return out


def markdown(rows: list[Row], header: str) -> str:
    lines = [
        header,
        "",
        "| figure | metric | paper | rwt | unit | note |",
        "|---|---|---:|---:|---|---|",
    ]
    for row in rows:
        cells = [fmt(row[key]).replace("|", "\\|") for key in ROW_KEYS]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def kept_rows(results: Path, run: Sequence[str], quick: bool) -> tuple[list[Row], list[str]]:
    """The rows of an earlier run of the same mode for modules not in ``run``, and those modules."""
    try:
        saved = json.loads(results.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return [], []
    if saved.get("quick") is not quick:
        return [], []
    modules = [m for m in saved.get("modules", []) if m in FIGURES and m not in run]
    figures = {FIGURES[m] for m in modules}
    return [row for row in saved.get("rows", []) if row.get("figure") in figures], modules


def in_paper_order(rows: list[Row]) -> list[Row]:
    """``rows`` sorted by module, in ``MODULES`` order (stable within a module)."""
    order = {FIGURES[name]: index for index, name in enumerate(MODULES)}
    return sorted(rows, key=lambda row: order.get(str(row["figure"]), len(order)))


def rewrite_readme(path: Path, section: str) -> None:
    """Put ``section`` between the markers of ``path``, appending them if missing."""
    text = path.read_text(encoding="utf-8") if path.exists() else "# Benchmarks\n"
    block = f"{BEGIN}\n{section}\n{END}"
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        tail = rest.split(END, 1)[1]
        text = head + block + tail
    else:
        text = text.rstrip("\n") + "\n\n## The paper's measurements\n\n" + block + "\n"
    path.write_text(text, encoding="utf-8")


def output_paths(
    quick: bool, results: Path | None = None, readme: Path | None = None
) -> tuple[Path, Path]:
    """The JSON results file and the README a run writes; paths given explicitly win.

    A full run updates the tracked ``RESULTS`` and ``README``; a quick one writes
    its copies under ``QUICK_DIR``, so a smoke test leaves the tracked numbers alone.
    """
    if quick:
        return results or QUICK_DIR / "paper.json", readme or QUICK_DIR / "README.md"
    return results or RESULTS, readme or README


def main(argv: Sequence[str] | None = None) -> list[Row]:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.paper", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="tiny counts (smoke test)")
    parser.add_argument("--only", help="comma-separated modules, e.g. tf,png")
    quick_dir = "with --quick, in benchmarks/results/quick/"
    parser.add_argument(
        "--results", type=Path, help=f"JSON output (benchmarks/results/paper.json; {quick_dir})"
    )
    parser.add_argument(
        "--readme", type=Path, help=f"README to update (benchmarks/README.md; {quick_dir})"
    )
    args = parser.parse_args(argv)
    results, readme = output_paths(args.quick, args.results, args.readme)
    names = available(args.only.split(",") if args.only else None)
    machine = f"{platform.machine()}, {platform.python_implementation()}"
    machine += f" {platform.python_version()}, {os.cpu_count()} cores"
    machine += f", load {os.getloadavg()[0]:.1f} at the start"  # times drift with it
    rows = run_all(names, args.quick)
    mode = "quick (smoke test, numbers mean nothing)" if args.quick else "full"
    Console().print(table(rows, f"rwt vs the Robot Web Tools paper ({mode})"))
    kept, kept_modules = kept_rows(results, names, args.quick) if args.only else ([], [])
    every = [name for name in MODULES if name in names or name in kept_modules]
    results.parent.mkdir(parents=True, exist_ok=True)
    saved_rows = in_paper_order(rows + kept)
    payload = {"quick": args.quick, "machine": machine, "modules": every, "rows": saved_rows}
    results.write_text(json.dumps(payload, indent=2) + "\n", encoding="utf-8")
    which = ", ".join(names)
    if kept_modules:
        which += f"; {', '.join(kept_modules)} kept from an earlier run"
    header = (
        f"`python -m benchmarks.paper` ({mode}; {machine}; modules: {which}). "
        "Regenerated by the runner: edit the text outside the markers."
    )
    readme.parent.mkdir(parents=True, exist_ok=True)
    rewrite_readme(readme, markdown(saved_rows, header))
    print(f"wrote {results} and {readme}", file=sys.stderr)
    return rows


if __name__ == "__main__":
    main()
