"""Replay the hardening campaign's attacks against ``rwt serve`` and measure what they cost.

Each class of the campaign (docs/decisions.md D37-D46, the bounds in docs/limits.md)
is replayed against a fresh ``rwt serve`` with the options it needs (``--webrtc``,
``--mcp``, a small ``--memory-budget``, a low RLIMIT_NOFILE...), from this checkout's
``src`` or ``$RWT_BENCH_SRC``'s (another checkout's ``src``: the figures before a
change). Meanwhile a bystander, a rosbridge WebSocket client in a process of its own
on another address (127.0.0.2), calls ``/rosapi/get_time`` every 50 ms
(``benchmarks/bystander.py``): 2 s of baseline, then the attack. Per class:

- the bystander's round trip p50 / p99 / max at baseline and under attack;
- the server's CPU seconds and peak RSS (``/proc``) during the attack;
- what the attacker (and any victim) got: status codes, refusals, errors;
- the verdict ``held`` when the bystander's max round trip under attack is at most its
  baseline max + 150 ms, the server's memory grew within the class's documented bound,
  and the attacker got no more than its rights with clear errors (each class's check).

The classes, how each was scaled to fit about 20 s, and their modules:
``benchmarks/attacks_webrtc.py`` (1, 2, 3, 6, 14, 15), ``benchmarks/attacks_mcp.py``
(4, 5, 7-13), ``benchmarks/attacks_flow.py`` (16, 17, 19) and ``benchmarks/attacks_http.py``
(30-32).

Run: ``python -m benchmarks.attacks [--class 1 --class 9 ...] [--scale 1]``,
``RWT_BENCH_SRC=/path/to/before/src python -m benchmarks.attacks`` for the figures before;
``--table`` prints the saved runs side by side. Results: ``results/attacks.json`` (one
run per source, this checkout or another's commit, the latest of each).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import asdict
from functools import partial
from pathlib import Path
from typing import Any

import anyio

from .attack_kit import Attack, Replay, replay

__all__ = ["all_attacks", "main", "run"]

RESULTS = Path(__file__).resolve().parent / "results" / "attacks.json"


def all_attacks() -> list[Attack]:
    """Every class, in the campaign's order."""
    from .attacks_flow import ATTACKS as FLOW  # noqa: PLC0415 (aiortc and mcp load late)
    from .attacks_http import ATTACKS as HTTP  # noqa: PLC0415
    from .attacks_mcp import ATTACKS as MCP  # noqa: PLC0415
    from .attacks_webrtc import ATTACKS as WEBRTC  # noqa: PLC0415

    def order(attack: Attack) -> int:
        return int(attack.number.split("+")[0])

    return sorted([*WEBRTC, *MCP, *FLOW, *HTTP], key=order)


def run(numbers: list[str] | None, scale: float = 1.0, log: bool = True) -> list[Replay]:
    """Replay the classes ``numbers`` (all when None), each on a fresh server."""
    chosen = [a for a in all_attacks() if numbers is None or a.number in numbers]
    replays = []
    for attack in chosen:
        if log:
            print(f"class {attack.number}: {attack.title} ...", file=sys.stderr, flush=True)
        result = anyio.run(partial(replay, attack, scale=scale))
        if log:
            print(_row(result), file=sys.stderr, flush=True)
        replays.append(result)
    return replays


def _row(r: Replay) -> str:
    why = f" ({'; '.join(r.reasons)})" if r.reasons else ""
    return (
        f"  {r.number:>5} rtt ms p50/p99/max {r.baseline.p50_ms:.1f}/{r.baseline.p99_ms:.1f}/"
        f"{r.baseline.max_ms:.0f} -> {r.attack.p50_ms:.1f}/{r.attack.p99_ms:.1f}/"
        f"{r.attack.max_ms:.0f} ({r.attack.calls} calls), CPU {r.cpu_s:.1f} s in "
        f"{r.attack_s:.0f} s, RSS {r.rss_start_mb:.0f} -> peak {r.rss_peak_mb:.0f} MB: "
        f"{r.verdict}{why}\n    {json.dumps(r.outcome)}"
    )


def _source() -> str:
    """``this checkout``, or the commit of ``$RWT_BENCH_SRC``'s checkout (else its path)."""
    src = os.environ.get("RWT_BENCH_SRC")
    if not src:
        return "this checkout"
    found = subprocess.run(
        ["git", "-C", src, "rev-parse", "--short", "HEAD"],
        capture_output=True,
        text=True,
        check=False,
    )
    return f"commit {found.stdout.strip()}" if found.returncode == 0 else src


def save(replays: list[Replay], scale: float) -> None:
    """Merge this run into ``results/attacks.json`` under its source, class by class."""
    saved: dict[str, Any] = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    runs = saved.setdefault("runs", {})
    run = runs.setdefault(_source(), {"classes": {}})
    run["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    run["scale"] = scale
    for r in replays:
        run["classes"][r.number] = asdict(r)
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps(saved, indent=2) + "\n")


def table() -> str:
    """The saved runs as one markdown table: a row per class and source."""
    saved = json.loads(RESULTS.read_text())
    lines = [
        "| class | server | bystander ms p50 / p99 / max, baseline | under attack | "
        "server CPU s / attack s | RSS MB start -> peak (bound) | verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    rows = [
        (number, source, r)
        for source, run in saved["runs"].items()
        for number, r in run["classes"].items()
    ]
    rows.sort(key=lambda x: (int(x[0].split("+")[0]), x[1] != "this checkout"))
    for number, source, r in rows:
        b, a = r["baseline"], r["attack"]
        bound = f" (+{r['bound_mb']:.0f})" if r["bound_mb"] is not None else ""
        name = "after" if source == "this checkout" else "before"
        verdict = r["verdict"] + (f": {'; '.join(r['reasons'])}" if r["reasons"] else "")
        lines.append(
            f"| {number} | {name} | {b['p50_ms']:.1f} / {b['p99_ms']:.1f} / {b['max_ms']:.0f} | "
            f"{a['p50_ms']:.1f} / {a['p99_ms']:.1f} / {a['max_ms']:.0f} | "
            f"{r['cpu_s']:.1f} / {r['attack_s']:.0f} | "
            f"{r['rss_start_mb']:.0f} -> {r['rss_peak_mb']:.0f}{bound} | {verdict} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Replay the classes asked for (all by default), print them, save the results."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--class", dest="classes", action="append", help="a class number")
    parser.add_argument("--scale", type=float, default=1.0, help="the attacks' length, x")
    parser.add_argument("--list", action="store_true", help="list the classes and exit")
    parser.add_argument("--table", action="store_true", help="print the saved runs and exit")
    args = parser.parse_args(argv)
    if args.list:
        for attack in all_attacks():
            print(f"{attack.number:>5}  {attack.title}: {attack.scaled}")
        return 0
    if args.table:
        print(table())
        return 0
    replays = run(args.classes, args.scale)
    save(replays, args.scale)
    print(f"rwt serve from {_source()}")
    for r in replays:
        print(_row(r))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
