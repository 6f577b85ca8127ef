"""What every scenario shares: the run context, measurements and their summary."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from ..loadgen.engine import LoopResult
from ..servers import ProcStats, Server

__all__ = [
    "Check",
    "Context",
    "Medians",
    "Metrics",
    "Run",
    "Variant",
    "percentile",
    "summary",
]

Metrics = dict[str, float]
"""One run's figures by name (rates per second, times in us or ms, bytes)."""


Stats = dict[str, float]
"""``median``, ``min`` and ``max`` of one metric over the runs."""
Medians = dict[str, dict[str, Stats]]
"""kind (``bare``/``rwt``) -> metric -> its ``Stats``."""
Context = dict[str, Medians]
"""The ``Medians`` of the variants already run, by ``Variant.key``."""
Check = Callable[[Medians, Context], tuple[str, str, bool | None]]
"""Judges a variant: (the figure checked, the target, met or None if not judged)."""


@dataclass(frozen=True)
class Run:
    """The context of one run of one variant.

    Attributes:
        server: the server under test (``server.kind`` is ``bare`` or ``rwt``).
        scale: 1.0 for the short form; the CI smoke test scales durations and
            counts by it.
        context: the medians of the variants run before (B15 runs at half of B1).
    """

    server: Server
    scale: float = 1.0
    context: Context = field(default_factory=dict)

    @property
    def kind(self) -> str:
        return self.server.kind

    @property
    def port(self) -> int:
        return self.server.port


@dataclass
class Variant:
    """One row of the table: a scenario in one configuration.

    Attributes:
        scenario: ``B1``...
        name: what the row measures, e.g. ``String 100 B, 1 -> 1``.
        run: measures one run; returns its metrics.
        primary: the metric compared in the bare/rwt/ratio columns.
        unit: the primary metric's unit.
        check: the target's judgement (see ``Check``).
        kinds: which servers it runs against.
        fresh_server: start new servers for every run (memory scenarios).
        server_args: extra ``rwt serve`` options.
    """

    scenario: str
    name: str
    run: Callable[[Run], Metrics]
    primary: str
    unit: str
    check: Check
    kinds: Sequence[str] = ("bare", "rwt")
    fresh_server: bool = False
    server_args: Sequence[str] = ()
    runs: int | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def key(self) -> str:
        """``B1 String 100 B, 1 -> 1``: unique within the suite."""
        return f"{self.scenario} {self.name}"


def percentile(values: Sequence[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values`` by the nearest-rank method."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    index = min(len(ordered) - 1, max(0, round(q * (len(ordered) - 1))))
    return ordered[index]


def summary(runs: Sequence[Metrics]) -> dict[str, dict[str, float]]:
    """Median, min and max of every metric over the runs."""
    names = sorted({k for r in runs for k in r})
    out: dict[str, dict[str, float]] = {}
    for name in names:
        values = [r[name] for r in runs if name in r]
        out[name] = {
            "median": statistics.median(values),
            "min": min(values),
            "max": max(values),
        }
    return out


def server_figures(
    before: ProcStats, after: ProcStats, loop: LoopResult, messages: float, window_s: float
) -> Metrics:
    """Server CPU per message (us), server and generator CPU share, and RSS (MB)."""
    cpu = after.cpu_s - before.cpu_s
    return {
        "server_cpu_us_per_msg": cpu / messages * 1e6 if messages else float("nan"),
        "server_cpu_pct": 100.0 * cpu / loop.wall_s,
        "generator_cpu_pct": 100.0 * loop.generator_cpu_s / loop.wall_s,
        "server_rss_mb": after.rss_bytes / 1e6,
        "window_s": window_s,
    }


def settle(seconds: float = 0.05) -> None:
    """Let the server close the previous run's connections."""
    time.sleep(seconds)
