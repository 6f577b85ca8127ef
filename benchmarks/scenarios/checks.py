"""Target judgements shared by the scenarios (docs/benchmarks.md's targets)."""

from __future__ import annotations

import math

from .common import Check, Context, Medians

__all__ = ["at_most", "med", "ratio_at_least", "ratio_of"]


def med(medians: Medians, kind: str, metric: str) -> float:
    """The median of ``metric`` for ``kind``, NaN when missing."""
    return medians.get(kind, {}).get(metric, {}).get("median", math.nan)


def ratio_of(medians: Medians, metric: str) -> float:
    """rwt's median over the bare relay's."""
    bare = med(medians, "bare", metric)
    return med(medians, "rwt", metric) / bare if bare else math.nan


def _ok(value: float, good: bool) -> bool | None:
    return None if math.isnan(value) else good


def ratio_at_least(metric: str, bound: float, *, cpu_bound: float | None = None) -> Check:
    """rwt/bare of ``metric`` >= ``bound`` (and server CPU per message <= ``cpu_bound`` x bare)."""

    def check(medians: Medians, context: Context) -> tuple[str, str, bool | None]:
        ratio = ratio_of(medians, metric)
        shown = f"{ratio:.2f}x"
        target = f">= {bound:g}x bare"
        met = _ok(ratio, ratio >= bound)
        if cpu_bound is not None:
            cpu = ratio_of(medians, "server_cpu_us_per_msg")
            shown += f"; CPU/msg {cpu:.2f}x"
            target += f"; CPU/msg <= {cpu_bound:g}x"
            met = _ok(cpu, bool(met) and cpu <= cpu_bound)
        return shown, target, met

    return check


def at_most(metric: str, bound: float, unit: str, kind: str = "rwt") -> Check:
    """``kind``'s median of ``metric`` <= ``bound``."""

    def check(medians: Medians, context: Context) -> tuple[str, str, bool | None]:
        value = med(medians, kind, metric)
        return f"{value:.3g} {unit}", f"<= {bound:g} {unit}", _ok(value, value <= bound)

    return check
