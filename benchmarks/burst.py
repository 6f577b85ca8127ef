"""B19, burst to one reading subscriber: a publisher sends N ``std_msgs/String``
publishes (100 B of data) over WebSocket as fast as it can; one subscriber reads
as fast as it can. Measured on ``rwt serve`` and on the bare relay (relay.py)
in the same run, with the same client code.

Reported: delivered/sent for each (rwt must deliver 100 %: input backpressure,
docs/limits.md, leaves the drop rule of D24 to subscribers that do not read)
and the throughput ratio rwt/bare (messages delivered per second, from the
first send to the last message received).

Run: ``python -m benchmarks.burst --count 200000`` (``--smoke``: 5,000 messages,
a few seconds).
"""

from __future__ import annotations

import argparse
import json
import threading
import time
from dataclasses import asdict, dataclass

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from .servers import start_server

__all__ = ["BurstResult", "run_burst"]

TOPIC = "/b19"
IDLE_S = 5.0
"""Seconds without a message after which the subscriber stops waiting for the rest."""
SMOKE_COUNT = 5_000


@dataclass(frozen=True)
class BurstResult:
    """One server's burst: messages sent, delivered, and delivered per second."""

    server: str
    sent: int
    delivered: int
    rate: float

    @property
    def delivered_ratio(self) -> float:
        return self.delivered / self.sent if self.sent else 0.0


def _frames(count: int) -> list[str]:
    pad = "x" * 92
    return [
        json.dumps({"op": "publish", "topic": TOPIC, "msg": {"data": f"{i:08d}{pad}"}})
        for i in range(count)
    ]


def _connect(url: str) -> ClientConnection:
    return connect(url, max_size=None, compression=None, open_timeout=20)


def _open_rwt(port: int) -> tuple[ClientConnection, ClientConnection]:
    sub = _connect(f"ws://127.0.0.1:{port}")
    sub.send(json.dumps({"op": "subscribe", "topic": TOPIC, "type": "std_msgs/String"}))
    sub.send(json.dumps({"op": "call_service", "service": "/rosapi/topics", "id": "ready"}))
    while '"service_response"' not in str(sub.recv(timeout=20)):
        pass  # the subscription is in place once the call is answered
    pub = _connect(f"ws://127.0.0.1:{port}")
    pub.send(json.dumps({"op": "advertise", "topic": TOPIC, "type": "std_msgs/String"}))
    return pub, sub


def _open_bare(port: int) -> tuple[ClientConnection, ClientConnection]:
    sub = _connect(f"ws://127.0.0.1:{port}/sub/b19")
    assert sub.recv(timeout=20) == "ready"
    pub = _connect(f"ws://127.0.0.1:{port}/pub/b19")
    assert pub.recv(timeout=20) == "ready"
    return pub, sub


def _burst(kind: str, port: int, frames: list[str]) -> BurstResult:
    pub, sub = (_open_rwt if kind == "rwt" else _open_bare)(port)
    received = 0
    last = 0.0

    def read() -> None:
        nonlocal received, last
        try:
            while received < len(frames):
                message = sub.recv(timeout=IDLE_S)
                if '"publish"' in str(message)[:40]:  # not rwt's status nor the relay's ready
                    received += 1
                    last = time.perf_counter()
        except (TimeoutError, ConnectionClosed):
            pass

    reader = threading.Thread(target=read)
    reader.start()
    start = time.perf_counter()
    for frame in frames:
        pub.send(frame)
    reader.join()
    for connection in (pub, sub):
        connection.close()
    elapsed = max(last - start, 1e-9)
    return BurstResult(kind, len(frames), received, received / elapsed)


def run_burst(count: int) -> dict[str, BurstResult]:
    """B19 on ``rwt serve`` and on the bare relay, one after the other; results by server."""
    frames = _frames(count)
    results: dict[str, BurstResult] = {}
    for kind in ("bare", "rwt"):
        with start_server(kind) as server:
            results[kind] = _burst(kind, server.port, frames)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=200_000, help="publishes to send")
    parser.add_argument("--smoke", action="store_true", help=f"{SMOKE_COUNT} messages")
    args = parser.parse_args()
    results = run_burst(SMOKE_COUNT if args.smoke else args.count)
    rwt, bare = results["rwt"], results["bare"]
    for result in (bare, rwt):
        print(json.dumps(asdict(result) | {"delivered_ratio": result.delivered_ratio}))
    print(
        f"B19 burst to one reading subscriber, {rwt.sent:,} x String 100 B over WebSocket: "
        f"rwt delivered {rwt.delivered:,}/{rwt.sent:,} ({100 * rwt.delivered_ratio:.1f} %) "
        f"at {rwt.rate:,.0f} msg/s; bare {bare.delivered:,}/{bare.sent:,} at "
        f"{bare.rate:,.0f} msg/s; ratio {rwt.rate / bare.rate:.2f}x"
    )


if __name__ == "__main__":
    main()
