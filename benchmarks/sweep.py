"""``python -m benchmarks sweep``: cost per message against four parameters.

The parameters: message size, subscribers, topics and idle connections.

Every point is run against the bare relay and ``rwt serve`` (interleaved,
medians of ``--runs``); cost per message is the server's CPU time per
published message, from /proc. Writes ``results/sweep.json`` and
``results/sweep.png`` (one panel per parameter, both servers on the same axes,
min-max as error bars).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from functools import partial

from . import msgs
from .loadgen.engine import Peer, close_all
from .runner import run_variant
from .scenarios.checks import med
from .scenarios.common import Metrics, Run, Variant
from .scenarios.load import topics_run
from .scenarios.throughput import Stream, stream_run

__all__ = ["sweep"]

_COST = "server_cpu_us_per_msg"


def _string(size: int) -> Stream:
    topic = "/sweep"
    return Stream(
        topic,
        "std_msgs/msg/String",
        partial(msgs.string_publish, topic, size=size),
        period=max(2, min(4096, (8 << 20) // size)),
        payload_bytes=size,
    )


def _with_idle(idle: int) -> Callable[[Run], Metrics]:
    def run(run: Run) -> Metrics:
        peers = [Peer(run.port, run.kind, [], receives=True, group="idle") for _ in range(idle)]
        try:
            return stream_run(run, _string(100), subscribers=1, duration_s=1.0)
        finally:
            close_all(peers)

    return run


def _points() -> dict[str, list[tuple[float, Callable[[Run], Metrics]]]]:
    def stream(size: int, subs: int) -> Callable[[Run], Metrics]:
        return lambda run: stream_run(run, _string(size), subscribers=subs, duration_s=1.0)

    def topics(count: int) -> Callable[[Run], Metrics]:
        return lambda run: topics_run(run, publishers=1, topics_each=count, duration_s=1.0)

    return {
        "message size (bytes)": [
            (s, stream(s, 1)) for s in (100, 1000, 10_000, 100_000, 1_000_000, 4_000_000)
        ],
        "subscribers": [(n, stream(100, n)) for n in (1, 3, 10, 30, 100)],
        "topics (1 publisher, 1 subscriber of all)": [(t, topics(t)) for t in (1, 10, 100, 1000)],
        "idle connections": [(i, _with_idle(i)) for i in (0, 50, 100, 200)],
    }


def _log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def sweep(args: argparse.Namespace) -> int:
    """Run every point, save the JSON and draw the plot."""
    data: dict[str, list[dict[str, object]]] = {}
    for axis, points in _points().items():
        data[axis] = []
        for x, fn in points:
            variant = Variant(
                "sweep", f"{axis} = {x:g}", fn, _COST, "us", lambda m, c: ("", "", None)
            )
            _log(variant.key)
            result = run_variant(variant, runs=args.runs, scale=1.0, uvloop=False, log=_log)
            medians = result.medians()
            data[axis].append(
                {
                    "x": x,
                    "summary": medians,
                    "errors": result.errors,
                    "bare": med(medians, "bare", _COST),
                    "rwt": med(medians, "rwt", _COST),
                }
            )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "sweep.json").write_text(json.dumps(data, indent=1) + "\n")
    _plot(data, args.out / "sweep.png")
    for axis, rows in data.items():
        print(
            f"{axis}: "
            + ", ".join(
                f"{r['x']:g}: bare {r['bare']:.1f} / rwt {r['rwt']:.1f} us"
                for r in rows  # type: ignore[str-format]
            )
        )
    return 1 if any(r["errors"] for rows in data.values() for r in rows) else 0


def _plot(data: dict[str, list[dict[str, object]]], path: object) -> None:
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    for ax, (axis, rows) in zip(axes.flat, data.items(), strict=True):
        xs = [float(r["x"]) for r in rows]  # type: ignore[arg-type]
        for kind, style in (("bare", "o--"), ("rwt", "s-")):
            ys, lo, hi = [], [], []
            for r in rows:
                stats = r["summary"].get(kind, {}).get(_COST, {})  # type: ignore[union-attr]
                ys.append(stats.get("median", float("nan")))
                lo.append(stats.get("median", 0) - stats.get("min", 0))
                hi.append(stats.get("max", 0) - stats.get("median", 0))
            ax.errorbar(
                xs,
                ys,
                yerr=[lo, hi],
                fmt=style,
                capsize=3,
                label="bare relay" if kind == "bare" else "rwt serve",
            )
        ax.set_xscale("log" if min(xs) > 0 else "symlog")
        if axis.startswith("message size"):
            ax.set_yscale("log")
        ax.set_xlabel(axis)
        ax.set_ylabel("server CPU per published message (us)")
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.suptitle("Cost per message: rwt serve vs bare websockets relay")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
