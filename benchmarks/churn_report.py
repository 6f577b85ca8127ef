"""B26's figures: the RSS curve's summary, the tables, and what tracemalloc saw grow.

``summarize`` turns the samples of ``benchmarks/churn.py`` (one dict a sample) into the
run's summary; ``table`` prints it; ``trace_growth`` compares two snapshots of
``benchmarks/churn_trace.py``.
"""

from __future__ import annotations

import json
import re
import statistics
import tracemalloc
from collections import Counter
from pathlib import Path
from typing import Any

__all__ = ["log_summary", "summarize", "table", "trace_growth", "verdict"]

MB = 1024 * 1024
WINDOW_S = 60.0
"""The RSS after the warm-up and at the end are medians of the samples in this long a
window (or a quarter of the churn after the warm-up, if shorter), so one sample's
allocator noise does not decide."""
FLAT_PCT = 5.0
FLAT_MB = 10.0
"""B26's verdict: the end within this much of the RSS after the warm-up (either)."""


def _median_rss(rows: list[dict[str, Any]], start: float, end: float) -> float:
    inside = [r["rss_mb"] for r in rows if start <= r["t_s"] <= end]
    return statistics.median(inside) if inside else float("nan")


def _slope_mb_per_h(rows: list[dict[str, Any]]) -> float:
    """The least-squares slope of RSS over time, MB an hour (0 with fewer than 3 samples)."""
    if len(rows) < 3:
        return 0.0
    ts = [r["t_s"] for r in rows]
    mean_t, mean_r = statistics.fmean(ts), statistics.fmean(r["rss_mb"] for r in rows)
    spread = sum((t - mean_t) ** 2 for t in ts)
    if not spread:
        return 0.0
    slope = sum((r["t_s"] - mean_t) * (r["rss_mb"] - mean_r) for r in rows) / spread
    return slope * 3600


def summarize(rows: list[dict[str, Any]], warmup_s: float, fronts: list[str]) -> dict[str, Any]:
    """The summary of a run's samples (``t_s``, ``phase``, ``rss_mb``, ``cycles_<front>``...).

    ``warmup_s``: where the warm-up ends (seconds from the start); ``fronts``: the front
    ends' names. RSS in MB (MiB), slopes in MB an hour, a cycle's share in bytes.
    """
    churn = [r for r in rows if r["phase"] == "churn"]
    end_t = churn[-1]["t_s"] if churn else 0.0
    window = max(min(WINDOW_S, (end_t - warmup_s) / 4), 0.0)
    warm = _median_rss(churn, warmup_s, warmup_s + window)
    end = _median_rss(churn, end_t - window, end_t)
    after = [r for r in churn if r["t_s"] >= warmup_s]
    slope = _slope_mb_per_h(after)
    cycles_after = 0
    if after:
        cycles_after = sum(after[-1][f"cycles_{f}"] - after[0][f"cycles_{f}"] for f in fronts)
    span_h = (after[-1]["t_s"] - after[0]["t_s"]) / 3600 if len(after) > 1 else 0.0
    per_cycle = slope * span_h * MB / cycles_after if cycles_after else 0.0
    drained = [r for r in rows if r["phase"] == "drain"]
    return {
        "seconds": end_t,
        "warmup_s": warmup_s,
        "rss_start_mb": rows[0]["rss_mb"] if rows else None,
        "rss_warm_mb": round(warm, 2),
        "rss_end_mb": round(end, 2),
        "rss_after_drain_mb": drained[-1]["rss_mb"] if drained else None,
        "rss_peak_mb": max((r["rss_mb"] for r in rows), default=None),
        "delta_mb": round(end - warm, 2),
        "delta_pct": round((end - warm) / warm * 100, 2) if warm else None,
        "slope_mb_per_h": round(slope, 2),
        "bytes_per_cycle": round(per_cycle),
        "cycles_after_warmup": cycles_after,
        "fds_warm_end": _ends(churn, warmup_s, "fds"),
        "threads_warm_end": _ends(churn, warmup_s, "threads"),
        "server_cpu_pct": round(statistics.fmean(r["cpu_pct"] for r in churn), 1)
        if churn
        else None,
    }


def _ends(rows: list[dict[str, Any]], warmup_s: float, key: str) -> list[Any]:
    after = [r[key] for r in rows if r["t_s"] >= warmup_s]
    return [after[0], after[-1]] if after else []


def verdict(summary: dict[str, Any], steady: dict[str, Any]) -> str:
    """``flat`` or ``grew`` (FLAT_PCT / FLAT_MB), and whether the steady subscriber lost any."""
    delta = summary["delta_mb"]
    flat = delta <= FLAT_MB or (summary["delta_pct"] or 0.0) <= FLAT_PCT
    served = steady.get("missing", 1) == 0 and steady.get("got", 0) > 0
    return ("flat" if flat else "grew") + (", steady served" if served else ", steady MISSED")


_EVENT = re.compile(r"event=(\S+)")


def log_summary(text: str, keep: int = 30) -> dict[str, Any]:
    """The server log's WARNING and ERROR lines: a count by ``event=`` (or first words),
    and the first ``keep`` of them."""
    lines = [ln for ln in text.splitlines() if " WARNING " in ln or " ERROR " in ln]
    kinds: Counter[str] = Counter()
    for line in lines:
        found = _EVENT.search(line)
        level = "ERROR" if " ERROR " in line else "WARNING"
        what = found[1] if found else " ".join(line.split(" ", 4)[-1].split()[:4])
        kinds[f"{level} {what}"] += 1
    tracebacks = text.count("Traceback (most recent call last)")
    return {"counts": dict(kinds.most_common()), "tracebacks": tracebacks, "first": lines[:keep]}


def table(record: dict[str, Any]) -> str:
    """The summary as Markdown: the RSS figures, then a row per front end."""
    s, steady = record["summary"], record["steady"]
    lines = [
        f"RSS: start {s['rss_start_mb']} MB, after the warm-up ({s['warmup_s']:.0f} s) "
        f"{s['rss_warm_mb']} MB, end {s['rss_end_mb']} MB: {s['delta_mb']:+} MB "
        f"({s['delta_pct']:+} %), slope {s['slope_mb_per_h']:+} MB/h "
        f"({s['bytes_per_cycle']:+} B a cycle over {s['cycles_after_warmup']} cycles), "
        f"peak {s['rss_peak_mb']} MB, after the drain {s['rss_after_drain_mb']} MB",
        f"descriptors {s['fds_warm_end']}, threads {s['threads_warm_end']} (after the "
        f"warm-up, end); server CPU {s['server_cpu_pct']} % of a core",
        f"steady subscriber: {steady.get('got')} of {steady.get('sent')} "
        f"(missing {steady.get('missing')}), longest silence "
        f"{steady.get('longest_silence_s')} s, {len(steady.get('gaps', []))} gaps over 1 s",
        f"verdict: {record['verdict']}",
        "",
        "| front end | rate (Hz) | cycles | failed | failures |",
        "|---|---|---|---|---|",
    ]
    for name, front in record["fronts"].items():
        kinds = "; ".join(f"{n}x {k}" for k, n in list(front["failures"].items())[:3])
        lines.append(
            f"| {name} | {front['hz']} | {front['cycles']} | {front['failed']} | {kinds} |"
        )
    return "\n".join(lines)


def _heap_lines(folder: Path) -> list[str]:
    """The growth of each figure of ``heap-<k>.json`` from the first dump to the last, MB."""
    first = json.loads((folder / "heap-0.json").read_text())
    last = json.loads((folder / "heap-1.json").read_text())
    figures = {"rss": (first["rss"], last["rss"]), "traced": (first["traced"], last["traced"])}
    if "rss_after_trim" in last:  # what glibc gave back at once: free heap, not live data
        figures["rss after malloc_trim"] = (first["rss"], last["rss_after_trim"])
    for part in ("glibc", "pymalloc"):
        for key, value in last[part].items():
            figures[f"{part}.{key}"] = (first[part].get(key, 0), value)
    return [
        f"    {name}: {a / MB:.2f} -> {b / MB:.2f} MB ({(b - a) / MB:+.2f})"
        if name != "pymalloc.arenas"
        else f"    {name}: {a} -> {b} ({b - a:+})"
        for name, (a, b) in figures.items()
    ]


def trace_growth(folder: Path, top: int = 12) -> str:
    """What grew from dump 0 to dump 1 of ``churn_trace`` in ``folder``: the heap's figures,
    what tracemalloc traced since (by the file of the allocation, and the ``top`` largest
    tracebacks, their nearest frames first) and the objects by type."""
    out = ["heap, from the end of the warm-up to the end of the drain:", *_heap_lines(folder)]
    if (folder / "snap-1.pickle").exists():
        out += _traced_lines(folder, top)
    before = json.loads((folder / "types-0.json").read_text())
    after = json.loads((folder / "types-1.json").read_text())
    grew = sorted(((after[k] - before.get(k, 0), k) for k in after), reverse=True)[:top]
    out.append("objects by type (gc), growth:")
    out.extend(f"    {n:+} {k} ({after[k]})" for n, k in grew if n > 0)
    holders = [k for k in after if k.startswith("weakref<-")]
    out.append(
        "what holds the last 200 weak references: "
        + ", ".join(f"{k[9:]} {after[k]}" for k in holders)
    )
    return "\n".join(out)


def _traced_lines(folder: Path, top: int) -> list[str]:
    first = tracemalloc.Snapshot.load(str(folder / "snap-0.pickle"))
    last = tracemalloc.Snapshot.load(str(folder / "snap-1.pickle"))
    out = []
    by_file = last.compare_to(first, "filename")
    total = sum(stat.size_diff for stat in by_file)
    out.append(f"tracemalloc: {total / 1024:+.1f} KiB alive that was allocated since; by file:")
    out.extend(
        f"    {stat.size_diff / 1024:+.1f} KiB {stat.traceback[0].filename}"
        for stat in by_file[:top]
    )
    out.append("by traceback (nearest frame first):")
    for stat in last.compare_to(first, "traceback")[:top]:
        out.append(f"  {stat.size_diff / 1024:+.1f} KiB, {stat.count_diff:+} blocks")
        out.extend(f"    {line}" for line in stat.traceback.format(limit=6, most_recent_first=True))
    return out
