"""``python -m benchmarks peer --edition ros2``: the ROS 2 rosbridge servers, web to web.

A WebSocket publisher (its own process, ``websockets``) advertises
``std_msgs/msg/String`` on a server and publishes 100 B whose data starts with
the publish time (``time.time()``, seconds); 1 or 10 WebSocket subscribers in
this process count and read the stamp (``ros2_bridge.Counter``). Servers, each
started afresh for each case, in one run:

- ``rwt``: ``rwt serve --dialect ros2`` (the in-memory graph);
- ``rosbridge``: the real rosbridge_suite 2.1.0 on ROS 2 Kilted wheels, and
  ``rs``: rosbridge-server-rs 0.1.6 (Rust, ROS 2 Jazzy wheels), both started by
  their tools (``ros2_bridge.PEERS``: ``RWT_ROSBRIDGE_ROS2_DIR``,
  ``RWT_ROSBRIDGE_RS_DIR``; unset: skipped, and the output says so). Both carry
  a web client's topic through DDS to the other web clients.

Cases: a burst of ``BURST`` messages sent as fast as the publisher can, and a
paced stream (``PACED``: 500 Hz to 1 subscriber, 50 Hz to 10, below the ~600
deliveries/s rosbridge_suite 2.1.0 sustains here), each for 1 -> 1 and 1 -> 10.
Figures as in ``ros2_bridge``: delivered msg/s (all subscribers, first timed
publish to last delivery), loss, p50/p99 latency, the server process's CPU per
delivery. Probes go first until every subscriber has one, and the server must be
idle before the timed part.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from .ros2_bridge import (
    DISCOVERY_S,
    LABELS,
    Counter,
    Result,
    _child,
    _cpu,
    _drain,
    _line,
    _percentile,
    _say,
    _settle,
    on_peer,
    peer_tools,
)
from .servers import ROOT, start_server

__all__ = ["BURST", "CASES", "WebCase", "main", "run_case", "table"]

BURST = 20_000
"""Messages in a burst."""


@dataclass(frozen=True, slots=True)
class WebCase:
    """One measurement: ``hz`` 0 is a burst of ``count`` messages, else ``seconds`` at ``hz``."""

    hz: int
    subscribers: int
    count: int = BURST

    @property
    def label(self) -> str:
        """``String burst 20000 1->10``, ``String 500 Hz 1->1``."""
        rate = f"burst {self.count}" if not self.hz else f"{self.hz} Hz"
        return f"String 100 B {rate} 1->{self.subscribers}"


CASES = [WebCase(0, 1), WebCase(0, 10), WebCase(500, 1), WebCase(50, 10)]
KINDS = ("rwt", "rosbridge", "rs")
WEB_LABELS = {**LABELS, "rwt": "rwt serve --dialect ros2"}

WEB_PUB = r"""
import json, sys, threading, time
from websockets.sync.client import connect
url, topic, hz, seconds, count = sys.argv[1:6]
hz, seconds, count = float(hz), float(seconds), int(count)
ws = connect(url, max_size=None, compression=None)
ws.send(json.dumps({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String"}))
threading.Thread(target=lambda: [m for m in ws], daemon=True).start()  # status, if any
go = threading.Event()
threading.Thread(target=lambda: (sys.stdin.readline(), go.set()), daemon=True).start()
print("ready", flush=True)
probe = json.dumps({"op": "publish", "topic": topic, "msg": {"data": "probe"}})
end = time.time() + 120
while not go.is_set() and time.time() < end:
    ws.send(probe)
    time.sleep(0.05)
time.sleep(0.3)  # the last probes are through
print(time.time(), flush=True)
head = '{"op":"publish","topic":"' + topic + '","msg":{"data":"'
sent, start, closed = 0, time.monotonic(), ""
try:
    while (sent < count) if not hz else (time.monotonic() - start < seconds):
        ws.send(head + f"{time.time():.6f}".ljust(100, "x") + '"}}')
        sent += 1
        if hz:
            delay = start + sent / hz - time.monotonic()
            if delay > 0:
                time.sleep(delay)
except Exception as exc:  # the server closed the publisher's connection
    rcvd = getattr(exc, "rcvd", None)
    closed = f"closed the publisher ({rcvd.code} {rcvd.reason})" if rcvd else repr(exc)
print(json.dumps({"sent": sent, "closed": closed}), flush=True)
sys.stdin.readline()
"""


async def _through(receiver: str, url: str, pid: int, case: WebCase, seconds: float) -> Result:
    topic = f"/peer_{receiver}_{case.hz}_{case.subscribers}"
    counters = [Counter() for _ in range(case.subscribers)]
    tasks = [asyncio.create_task(c.run(url, topic, "string")) for c in counters]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    args = (url, topic, str(case.hz), str(seconds), str(case.count))
    try:
        async with _child(WEB_PUB, *args, env=env) as pub:
            await _line(pub)  # ready
            await asyncio.wait_for(
                asyncio.gather(*(c.probed.wait() for c in counters)), DISCOVERY_S
            )
            await _settle(pid)
            await _say(pub)
            start = float(await _line(pub))
            cpu0 = _cpu(pid)
            sent_task = asyncio.create_task(_line(pub, seconds + DISCOVERY_S))
            cpu1 = await _drain(counters, pid, sent_task)
            ended = json.loads(await sent_task)
            sent = ended["sent"]
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    latencies = [x for c in counters for x in c.latencies]
    delivered = len(latencies)
    last = max(c.last for c in counters)
    return Result(
        receiver=receiver,
        case=case.label,
        subscribers=case.subscribers,
        sent=sent,
        delivered=delivered,
        msg_per_s=delivered / max(last - start, 1e-9) if delivered else 0.0,
        loss=1 - delivered / max(sent * case.subscribers, 1),
        p50_ms=_percentile(latencies, 0.5) * 1e3,
        p99_ms=_percentile(latencies, 0.99) * 1e3,
        cpu_us_per_delivery=(cpu1 - cpu0) / max(delivered, 1) * 1e6,
        note=ended["closed"],
    )


async def run_case(
    receiver: str, case: WebCase, seconds: float, domain: int, tools: Path | None = None
) -> Result:
    """One ``case`` on ``receiver`` (``rwt``, or a peer of ``PEERS`` with ``tools``).

    Raises:
        RuntimeError: a server or the publisher did not start or ended early.
        TimeoutError: a subscriber saw no probe within ``DISCOVERY_S``.
    """
    if receiver == "rwt":
        extra = ["--dialect", "ros2", "--no-tf"]
        with await asyncio.to_thread(start_server, receiver, extra=extra) as server:
            url = f"ws://127.0.0.1:{server.port}"
            return await _through(receiver, url, server.process.pid, case, seconds)
    assert tools is not None

    async def measure(url: str, pid: int) -> Result:
        return await _through(receiver, url, pid, case, seconds)

    return await on_peer(receiver, tools, domain, measure)


def table(results: list[Result]) -> str:
    """The Markdown table of ``results``."""
    lines = [
        "| case | server | sent | delivered msg/s | loss | p50 ms | p99 ms | CPU us/delivery "
        "| note |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in results:
        lines.append(
            f"| {r.case} | {WEB_LABELS[r.receiver]} | {r.sent} | {r.msg_per_s:,.0f} "
            f"| {r.loss:.1%} | {r.p50_ms:.1f} | {r.p99_ms:.1f} | {r.cpu_us_per_delivery:.0f} "
            f"| {r.note} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run every case on every server; print the Markdown table (``--json``: every figure)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks peer --edition ros2")
    parser.add_argument("--seconds", type=float, default=5.0, help="paced publishing per case")
    parser.add_argument("--receivers", default=",".join(KINDS), help="rwt,rosbridge,rs")
    parser.add_argument("--domain", type=int, default=120 + os.getpid() % 10, help="ROS_DOMAIN_ID")
    parser.add_argument("--burst", type=int, default=BURST, help="messages in a burst")
    parser.add_argument("--json", type=Path, help="write the results here")
    args = parser.parse_args(argv)
    receivers = [r for r in args.receivers.split(",") if r]
    tools = peer_tools(receivers)
    cases = [WebCase(c.hz, c.subscribers, args.burst) for c in CASES]

    async def run_all() -> list[Result]:
        results = []
        for case in cases:
            for receiver in receivers:
                print(f"{case.label} {receiver}...", file=sys.stderr, flush=True)
                started = time.monotonic()
                where = tools.get(receiver)
                result = await run_case(receiver, case, args.seconds, args.domain, where)
                print(f"  {time.monotonic() - started:.0f} s", file=sys.stderr, flush=True)
                results.append(result)
        return results

    results = asyncio.run(run_all())
    print(table(results))
    if args.json:
        args.json.write_text(json.dumps([asdict(r) for r in results], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
