"""``python -m benchmarks compare REF [SCENARIO...]``: this checkout against an older one.

A change that must keep rwt's speed (a refactor, a new layer on the hot path) is
measured against the commit before it in one run: the suite's variants run with
``rwt serve`` from a detached worktree of ``REF`` (kind ``base``) and from this
checkout (kind ``rwt``), alternating run by run as the suite alternates the relay
and rwt, so both see the same machine state. The load generator and scenarios are
this checkout's; only the server differs. The table gives each variant's primary
metric for both and the ratio rwt/base (above 1 is faster for rates, slower for
times: the unit column says which). Results go to ``results/compare.json``.

For the scripts with their own servers (``ros2``, ``scaleout``), set
``RWT_BENCH_SRC`` to the worktree's ``src`` and run them in turn with and without it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .report import fmt_value, median_ratio
from .runner import VariantResult, run_variant
from .scenarios import all_variants
from .scenarios.common import Context
from .servers import ROOT

__all__ = ["main"]

RESULTS = Path(__file__).resolve().parent / "results" / "compare.json"
DEFAULT = ("B1", "B2")


def _log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _worktree(ref: str, where: Path) -> str:
    """Check ``ref`` out detached at ``where``; returns its commit id."""
    sha = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--verify", f"{ref}^{{commit}}"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(where), sha],
        check=True,
    )
    return sha


def _ratio(result: VariantResult) -> float:
    return median_ratio(result, "rwt", over="base")


def _table(results: list[VariantResult]) -> str:
    lines = ["| id | scenario | unit | base | rwt | rwt/base |", "|---|---|---|---|---|---|"]
    for r in results:
        medians = r.medians()
        cells = []
        for kind in ("base", "rwt"):
            stats = medians.get(kind, {}).get(r.variant.primary)
            cells.append("-" if stats is None else fmt_value(stats["median"]))
        v = r.variant
        lines.append(
            f"| {v.scenario} | {v.name} | {v.unit} | {cells[0]} | {cells[1]} | {_ratio(r):.2f} |"
        )
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """Parse ``REF [SCENARIO...] [--runs N]`` and run; exit 1 when a run failed its check."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks compare", description=__doc__)
    parser.add_argument("ref", help="the baseline: a commit, branch or tag")
    parser.add_argument("scenarios", nargs="*", help=f"default: {' '.join(DEFAULT)}")
    parser.add_argument("--runs", type=int, default=5, help="runs per server and variant")
    parser.add_argument("--smoke", action="store_true", help="one tiny run of each (CI)")
    args = parser.parse_args(argv)
    if args.smoke:
        args.runs = 1
    wanted = {s.upper() for s in args.scenarios} or set(DEFAULT)
    variants = [v for v in all_variants(soak=False, smoke=args.smoke) if v.scenario in wanted]
    results: list[VariantResult] = []
    context: Context = {}
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="rwt-base-") as tmp:
        where = Path(tmp) / "base"
        sha = _worktree(args.ref, where)
        try:
            for variant in variants:
                _log(variant.key)
                paired = dataclasses.replace(variant, kinds=("base", "rwt"))
                result = run_variant(
                    paired,
                    runs=args.runs,
                    scale=0.1 if args.smoke else 1.0,
                    uvloop=False,
                    log=_log,
                    context=context,
                    sources={"base": where / "src"},
                )
                context[variant.key] = result.medians()
                results.append(result)
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(where)], check=False
            )
    print(f"base {sha[:10]} vs this checkout, {args.runs} runs per variant, medians")
    print(_table(results))
    _log(f"{(time.perf_counter() - started) / 60:.1f} min")
    if not args.smoke:
        _save(sha, args.runs, results)
    errors = [e for r in results for e in r.errors]
    for error in errors:
        _log(f"error: {error}")
    return 1 if errors else 0


def _save(sha: str, runs: int, results: list[VariantResult]) -> None:
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(
        json.dumps(
            {
                "base": sha,
                "runs": runs,
                "variants": [
                    {"key": r.variant.key, "medians": r.medians(), "ratio": _ratio(r)}
                    for r in results
                ],
            },
            indent=1,
        )
    )
