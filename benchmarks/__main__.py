"""``python -m benchmarks run [SCENARIO...]``: the benchmark suite, and ``sweep``.

Runs each selected scenario (default: B1-B11, B14, B15) against the bare relay
and ``rwt serve`` in the same run, prints the table (medians of ``--runs`` runs
with min-max, the rwt/bare ratio, the target and whether it was met, and the
load generator's CPU to show its headroom), writes
``benchmarks/results/suite.json`` and puts the table into
``benchmarks/README.md``. ``--soak`` runs B15 for 30 minutes. ``--smoke`` runs
every variant once on tiny counts without touching the README (CI).
``peer`` compares with a running rosbridge_suite (benchmarks/peer.py); ``ros2``
measures the ROS 2 bridge (benchmarks/ros2_bridge.py; ``ros2 --foxglove``: ROS 2
images to Foxglove readers, benchmarks/ros2_foxglove.py; ``ros2 --graph``: how soon
rosapi lists a new node's topics, benchmarks/ros2_graph.py); ``console`` the web
console in Chromium (benchmarks/console.py); ``rosbag`` records and plays against
the real ROS 1 rosbag (B22, benchmarks/ros1_bag.py); ``compare REF`` this checkout
against an older commit (benchmarks/compare.py).
the real ROS 1 rosbag (B22, benchmarks/ros1_bag.py); ``foxglove`` rwt's Foxglove
server beside the Foxglove SDK's (benchmarks/foxglove.py).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .report import markdown_table, save_json, update_readme
from .runner import VariantResult, run_variant
from .scenarios import all_variants, fuzz
from .scenarios.common import Context

RESULTS = Path(__file__).resolve().parent / "results"
README = Path(__file__).resolve().parent / "README.md"


def _log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    """Run the selected scenarios; exit status 1 when a correctness check failed."""
    scale = 0.1 if args.smoke else 1.0
    runs = 1 if args.smoke else args.runs
    fuzz.SETTINGS["frames"] = args.frames
    variants = all_variants(soak=args.soak, smoke=args.smoke)
    wanted = {s.upper() for s in args.scenarios}
    # B18 (a million fuzzed frames) runs only when named.
    selected = [v for v in variants if v.scenario in wanted or (not wanted and v.scenario != "B18")]
    results: list[VariantResult] = []
    context: Context = {}
    started = time.perf_counter()
    for variant in selected:
        _log(f"{variant.key}")
        result = run_variant(
            variant, runs=runs, scale=scale, uvloop=args.uvloop, log=_log, context=context
        )
        result.shown, result.target, result.met = variant.check(result.medians(), context)
        context[variant.key] = result.medians()
        results.append(result)
    table = markdown_table(results)
    elapsed = time.perf_counter() - started
    header = (
        f"Last run: `python -m benchmarks run{' --soak' if args.soak else ''}`, "
        f"{runs} runs per variant, {elapsed / 60:.1f} min"
        f"{', uvloop' if args.uvloop else ''}. Medians [min-max]."
    )
    print(table)
    if not args.smoke:
        save_json(results, args.out / "suite.json", vars(args) | {"out": str(args.out)})
        if not args.scenarios:
            update_readme(table, header, README)
    errors = [e for r in results for e in r.errors]
    for error in errors:
        _log(f"error: {error}")
    return 1 if errors else 0


def main(argv: list[str] | None = None) -> int:
    """Parse the command line and run."""
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["peer"]:  # its own options (benchmarks/peer.py)
        from .peer import main as peer_main  # noqa: PLC0415

        return peer_main(argv[1:])
    if argv[:1] == ["console"]:  # its own options (benchmarks/console.py)
        from .console import main as console_main  # noqa: PLC0415

        return console_main(argv[1:])
    if argv[:1] == ["ros2"] and "--foxglove" in argv:  # benchmarks/ros2_foxglove.py
        from .ros2_foxglove import main as ros2_foxglove_main  # noqa: PLC0415

        return ros2_foxglove_main([a for a in argv[1:] if a != "--foxglove"])
    if argv[:1] == ["ros2"] and "--graph" in argv:  # benchmarks/ros2_graph.py
        from .ros2_graph import main as ros2_graph_main  # noqa: PLC0415

        return ros2_graph_main([a for a in argv[1:] if a != "--graph"])
    if argv[:1] == ["ros2"]:  # its own options (benchmarks/ros2_bridge.py)
        from .ros2_bridge import main as ros2_main  # noqa: PLC0415

        return ros2_main(argv[1:])
    if argv[:1] == ["compare"]:  # its own options (benchmarks/compare.py)
        from .compare import main as compare_main  # noqa: PLC0415

        return compare_main(argv[1:])
    if argv[:1] == ["foxglove"]:  # its own options (benchmarks/foxglove.py)
        from .foxglove import main as foxglove_main  # noqa: PLC0415

        return foxglove_main(argv[1:])
    if argv[:1] == ["scaleout"]:  # its own options (benchmarks/scaleout.py)
        from .scaleout import main as scaleout_main  # noqa: PLC0415

        return scaleout_main(argv[1:])
    if argv[:1] == ["rosbag"]:  # its own options (benchmarks/ros1_bag.py)
        from .ros1_bag import main as rosbag_main  # noqa: PLC0415

        return rosbag_main(argv[1:])
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("peer", help="B1, B2, B7 against rosbridge_suite (ROS 1), rwt and the relay")
    sub.add_parser("console", help="the web console in Chromium: input latency, CPU, streams")
    sub.add_parser("ros2", help="real ROS 2 to WebSocket: rwt --ros2, rosbridge_suite 2.1.0, rclpy")
    sub.add_parser("foxglove", help="rwt's Foxglove server beside the Foxglove SDK's (PyPI)")
    sub.add_parser("rosbag", help="B22: rwt record and play against the real ROS 1 rosbag")
    sub.add_parser("compare", help="this checkout against REF (a commit), e.g. B1 B2, one run")
    p_run = sub.add_parser("run", help="run scenarios and print the table")
    p_run.add_argument("scenarios", nargs="*", help="B1 ... B18 (default: all but B18)")
    p_run.add_argument("--runs", type=int, default=5, help="runs per server and variant")
    p_run.add_argument("--soak", action="store_true", help="B15 for 30 min")
    p_run.add_argument("--smoke", action="store_true", help="one tiny run of each (CI)")
    p_run.add_argument("--uvloop", action="store_true", help="run both servers on uvloop")
    p_run.add_argument("--out", type=Path, default=RESULTS, help="where suite.json goes")
    p_run.add_argument("--frames", type=int, default=1_000_000, help="B18: fuzzed frames to send")
    sub.add_parser(
        "scaleout",
        help="rwt over Zenoh: latency, --workers, vs bare Zenoh; --workers 1,2,4: the scale table",
    )
    p_sweep = sub.add_parser("sweep", help="scaling sweep and its plots")
    p_sweep.add_argument("--runs", type=int, default=3)
    p_sweep.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    if args.command == "run":
        return run(args)
    from .sweep import sweep  # noqa: PLC0415  (matplotlib only when plotting)

    return sweep(args)


if __name__ == "__main__":
    sys.exit(main())
