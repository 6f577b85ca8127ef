"""``python -m benchmarks scaleout --cost-model``: the constants of docs/scaling.md's cost model.

For each subscriber count S (default 10, 50, 100), servers of 1, 2 and 4 workers
(``--workers``) run side by side, each with one fan-out of 1 publisher and S
subscribers kept connected (``fanout_raw.FanOut``). Bursts of ``burst_s`` then
alternate between them, in the order 1, 2, 4, 4, 2, 1 worker(s) per round, so a
drift of the machine's speed weighs on every server alike; a burst's figure is
the server's CPU (every thread of every process, from ``/proc``) per message.

From the medians it fits, per worker count N, ``C(N, S) = a(N) + S * d(N)`` (least
squares over S): ``d(N)`` is the CPU per delivery (us), ``a(N)`` the CPU per message
that does not depend on the subscribers. Then ``a(N) = m + e + (N - 1) * r`` for
N > 1, ``a(1) = m``: ``m`` is paid once per message (the client's frame, its
decoding, the routing), ``e`` once per message when other workers subscribe (the
publishing worker's CDR encode and Zenoh put), ``r`` by each other worker that
subscribes (Zenoh's receive, the hand-over to its event loop, the CDR decode,
routing and frame building there). Per-thread CPU (``proctree.by_role``) comes
with each figure.
"""

from __future__ import annotations

import contextlib
import statistics
import sys
from collections import Counter
from typing import Any

from .fanout_raw import FanOut
from .proctree import by_role, tree_cpu_ns, tree_threads
from .scale_workers import serve_workers

__all__ = ["cost_table", "fit", "measure_costs"]


def measure_costs(
    subscribers: list[int],
    workers: list[int],
    rounds: int,
    burst_s: float,
    placement: str = "none",
) -> dict[str, Any]:
    """Median server CPU per message (us) per (workers, subscribers), in paired bursts.

    ``placement``: the ``--placement`` of the servers of more than one worker (D57).

    Returns:
        ``"N{n} S{s}"``: ``us_per_msg`` (median of the bursts), ``bursts`` (each
        burst's us per message) and ``roles`` (us per message by thread role).
    """
    found: dict[str, Any] = {}
    for subs in subscribers:
        with contextlib.ExitStack() as stack:
            servers = {
                n: stack.enter_context(
                    serve_workers(n, ["--placement", placement] if n > 1 else [])
                )
                for n in workers
            }
            fans = {}
            for n, (_, port) in servers.items():
                fans[n] = FanOut(port, subs)
                stack.callback(fans[n].close)
            for n in workers:
                fans[n].burst(burst_s / 2, servers[n][0], tree_cpu_ns)  # warm
            bursts: dict[int, list[float]] = {n: [] for n in workers}
            roles: dict[int, Counter[str]] = {n: Counter() for n in workers}
            messages: dict[int, float] = dict.fromkeys(workers, 0.0)
            for _ in range(rounds):
                for n in [*workers, *reversed(workers)]:
                    pid = servers[n][0]
                    print(f"S {subs}, workers {n}", file=sys.stderr, flush=True)
                    before = tree_threads(pid)
                    got, ns = fans[n].burst(burst_s, pid, tree_cpu_ns)
                    roles[n] += by_role(before, tree_threads(pid), pid)
                    messages[n] += got / subs
                    bursts[n].append(ns / 1e3 / max(got / subs, 1))
        for n in workers:
            found[f"N{n} S{subs}"] = {
                "us_per_msg": statistics.median(bursts[n]),
                "bursts": bursts[n],
                "roles": {
                    key[:-3]: value / 1e3 / max(messages[n], 1)
                    for key, value in roles[n].items()
                    if key.endswith(" ns") and value
                },
            }
    return found


def fit(found: dict[str, Any], subscribers: list[int], workers: list[int]) -> dict[str, float]:
    """The cost model's constants (us) from ``measure_costs``'s medians (module doc).

    Returns:
        ``a{n}`` and ``d{n}`` per worker count, and ``m``, ``e``, ``r`` when 1 and at
        least two larger counts were measured (``r``: least squares over them).
    """
    out: dict[str, float] = {}
    for n in workers:
        ys = [found[f"N{n} S{s}"]["us_per_msg"] for s in subscribers]
        slope, intercept = statistics.linear_regression(subscribers, ys)
        out[f"a{n}"], out[f"d{n}"] = intercept, slope
    more = [n for n in workers if n > 1]
    if 1 in workers and len(more) >= 2:
        r, base = statistics.linear_regression([n - 1 for n in more], [out[f"a{n}"] for n in more])
        out["m"], out["r"] = out["a1"], r
        out["e"] = base - out["a1"]
    return out


def cost_table(found: dict[str, Any], subscribers: list[int], workers: list[int]) -> str:
    """The medians and the fit as Markdown lines."""
    lines = [
        "| subscribers | "
        + " | ".join(f"{n} worker(s): us/msg (us/delivery)" for n in workers)
        + " |",
        "|---|" + "---|" * len(workers),
    ]
    for subs in subscribers:
        cells = [found[f"N{n} S{subs}"]["us_per_msg"] for n in workers]
        lines.append(f"| {subs} | " + " | ".join(f"{c:.1f} ({c / subs:.2f})" for c in cells) + " |")
    constants = fit(found, subscribers, workers)
    lines += ["", "| constant | us |", "|---|---|"]
    lines += [f"| {key} | {value:.2f} |" for key, value in constants.items()]
    return "\n".join(lines)
