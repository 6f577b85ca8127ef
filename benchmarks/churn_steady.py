"""B26's robot and its steady subscriber: two rosbridge clients that stay for the whole soak.

``python -m benchmarks.churn_steady URL [--hz 20]`` (a process of its own, started by
``benchmarks/churn.py``), two ``websockets`` connections to ``URL``:

- **the robot** advertises ``STEADY_TOPIC`` (``std_msgs/msg/String``) and publishes
  its sequence number (``"0"``, ``"1"``...) at ``--hz`` on absolute deadlines (a late
  tick publishes at once; none is skipped), and provides ``SERVICE``
  (``std_srvs/srv/SetBool``), answering every call ``success: true``: the service
  every churning client calls;
- **the steady subscriber** subscribes to ``STEADY_TOPIC`` and counts what it gets:
  a sequence number past the next one expected counts the ones between as missing,
  and each silence longer than ``GAP_S`` is a gap (its start on the monotonic clock
  and its length, seconds).

``ready`` is printed once the subscriber has its first message; then a JSON line every
``REPORT_S`` (``{"t": monotonic s, "sent": n, "got": n, "missing": n, "calls": n,
"longest_silence_s": s, "gaps": [[start, length], ...]}``, the gaps of the last
``MAX_GAPS``). On SIGTERM the robot stops publishing, the subscriber waits up to
``DRAIN_S`` for the last one, and a last line with ``"final": true`` is printed. It
never imports rwt, so it serves any rosbridge server.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import signal
import time
from dataclasses import dataclass, field

from websockets.asyncio.client import ClientConnection, connect

__all__ = ["SERVICE", "SERVICE_TYPE", "STEADY_TOPIC", "STRING", "main"]

STEADY_TOPIC = "/soak/steady"
STRING = "std_msgs/msg/String"
SERVICE = "/soak/set_bool"
SERVICE_TYPE = "std_srvs/srv/SetBool"
GAP_S = 1.0
"""A silence of the steady subscriber longer than this is a gap (20 periods at 20 Hz)."""
REPORT_S = 1.0
MAX_GAPS = 100
DRAIN_S = 2.0
"""How long the subscriber waits for the last message after the robot stopped."""


@dataclass
class Counts:
    """What the robot sent and served, what the steady subscriber got."""

    sent: int = 0
    got: int = 0
    missing: int = 0
    calls: int = 0
    expected: int = 0
    last_at: float = 0.0
    longest_silence_s: float = 0.0
    gaps: list[list[float]] = field(default_factory=list)

    def heard(self, seq: int, now: float) -> None:
        """The subscriber got message ``seq`` at ``now`` (monotonic s)."""
        if seq < self.expected:
            return  # a repeat: never expected of rosbridge, not counted
        self.missing += seq - self.expected
        self.expected = seq + 1
        self.got += 1
        if self.last_at:
            silence = now - self.last_at
            self.longest_silence_s = max(self.longest_silence_s, silence)
            if silence > GAP_S:
                self.gaps = [*self.gaps, [round(self.last_at, 3), round(silence, 3)]][-MAX_GAPS:]
        self.last_at = now

    def line(self, final: bool = False) -> str:
        """The JSON line of the module's docstring."""
        record = {
            "t": round(time.monotonic(), 3),
            "sent": self.sent,
            "got": self.got,
            "missing": self.missing,
            "calls": self.calls,
            "longest_silence_s": round(self.longest_silence_s, 3),
            "gaps": self.gaps,
        }
        if final:
            record["final"] = True
        return json.dumps(record)


async def _robot(ws: ClientConnection, hz: float, counts: Counts, stop: asyncio.Event) -> None:
    await ws.send(json.dumps({"op": "advertise", "topic": STEADY_TOPIC, "type": STRING}))
    await ws.send(json.dumps({"op": "advertise_service", "service": SERVICE, "type": SERVICE_TYPE}))

    async def serve() -> None:
        async for frame in ws:
            op = json.loads(frame)
            if op.get("op") != "call_service":
                continue
            counts.calls += 1
            answer = {
                "op": "service_response",
                "service": op["service"],
                "id": op.get("id"),
                "values": {"success": True, "message": "ok"},
                "result": True,
            }
            await ws.send(json.dumps(answer))

    server = asyncio.ensure_future(serve())
    due = time.monotonic()
    try:
        while not stop.is_set():
            msg = {"data": str(counts.sent)}
            await ws.send(json.dumps({"op": "publish", "topic": STEADY_TOPIC, "msg": msg}))
            counts.sent += 1
            due = max(due + 1.0 / hz, time.monotonic())
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), due - time.monotonic())
    finally:
        server.cancel()


async def _subscriber(ws: ClientConnection, counts: Counts, first: asyncio.Event) -> None:
    await ws.send(json.dumps({"op": "subscribe", "topic": STEADY_TOPIC, "type": STRING}))
    async for frame in ws:
        op = json.loads(frame)
        if op.get("op") == "publish" and op.get("topic") == STEADY_TOPIC:
            counts.heard(int(op["msg"]["data"]), time.monotonic())
            first.set()


async def _run(url: str, hz: float) -> None:
    stop = asyncio.Event()
    asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, stop.set)
    counts = Counts()
    first = asyncio.Event()
    async with (
        connect(url, max_size=None, compression=None, open_timeout=60) as robot_ws,
        connect(url, max_size=None, compression=None, open_timeout=60) as steady_ws,
    ):
        listening = asyncio.ensure_future(_subscriber(steady_ws, counts, first))
        await asyncio.sleep(0.2)  # the subscription stands before the first publish
        robot = asyncio.ensure_future(_robot(robot_ws, hz, counts, stop))
        await asyncio.wait_for(first.wait(), 60)
        print("ready", flush=True)
        while not stop.is_set():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), REPORT_S)
            print(counts.line(), flush=True)
        await robot
        for _ in range(round(DRAIN_S / 0.05)):
            if counts.expected >= counts.sent:
                break
            await asyncio.sleep(0.05)
        counts.missing += counts.sent - counts.expected  # never came
        listening.cancel()
        print(counts.line(final=True), flush=True)


def main(argv: list[str] | None = None) -> None:
    """Run until SIGTERM (see the module's docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("url")
    parser.add_argument("--hz", type=float, default=20.0)
    args = parser.parse_args(argv)
    asyncio.run(_run(args.url, args.hz))


if __name__ == "__main__":
    main()
