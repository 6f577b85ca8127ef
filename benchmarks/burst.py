"""B19, burst to one reading subscriber: a publisher sends N ``std_msgs/String``
publishes (100 B of data) over WebSocket as fast as it can; one subscriber reads
as fast as it can. Measured on ``rwt serve`` and on the bare relay (relay.py)
in the same run, with the same client code.

Reported: delivered/sent for each (rwt must deliver 100 %: input backpressure,
docs/limits.md, leaves the drop rule of D24 to subscribers that do not keep up)
and the throughput ratio rwt/bare (messages delivered per second, from the
first send to the last message received).

The slow-reader variant (``--slow-reader``) runs two more scenarios on both
servers, each with a slow reader present that must not slow anyone else
(docs/limits.md, hold budget):

- the same burst while a second subscriber takes one message every 10 ms:
  the reading subscriber's delivered/sent and its rate against the bare
  relay's plain B19;
- a 30 Hz stream of 320x240 rgb8 ``sensor_msgs/Image`` (300 KB of JSON each)
  for ``STREAM_FRAMES`` frames, the publisher paced at 30 Hz, a bystander
  reading as fast as it can and a slow reader at 10 frames/s: the bystander's
  rate as a percentage of the 30 Hz publish rate (frames it got over the time
  from the first publish to its last frame).

Run: ``python -m benchmarks.burst --count 200000 [--slow-reader]``
(``--smoke``: 5,000 messages and a 60-frame stream, a few seconds).
"""

from __future__ import annotations

import argparse
import base64
import json
import threading
import time
from dataclasses import asdict, dataclass

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from .servers import start_server

__all__ = ["BurstResult", "StreamResult", "run_burst", "run_slow_reader"]

TOPIC = "/b19"
IDLE_S = 5.0
"""Seconds without a message after which the subscriber stops waiting for the rest."""
SMOKE_COUNT = 5_000
SLOW_PERIOD_S = 0.01
"""The slow reader of the burst variant takes one message this often (100 messages/s)."""
STREAM_TOPIC = "/b19_image"
STREAM_HZ = 30.0
STREAM_FRAMES = 300  # 10 s at 30 Hz
SMOKE_STREAM_FRAMES = 60
STREAM_SLOW_PERIOD_S = 0.1
"""The slow reader of the stream takes one frame this often (10 frames/s)."""


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


SLOW_QUEUE = (4, 2)
"""The slow reader's client buffer, frames (high, low): it pauses reading the socket
above 4 frames and resumes at 2, so it reads steadily at its pace; websockets'
default (16, 4) pauses for 12 frames at a time, which at 10 frames/s looks like
a peer that stopped reading (docs/limits.md, ``INPUT_STALL_S``)."""


def _connect(url: str, slow: bool = False) -> ClientConnection:
    queue = SLOW_QUEUE if slow else 16
    return connect(url, max_size=None, compression=None, open_timeout=20, max_queue=queue)


def _subscribe_rwt(port: int, topic: str, type_name: str, slow: bool) -> ClientConnection:
    sub = _connect(f"ws://127.0.0.1:{port}", slow)
    sub.send(json.dumps({"op": "set_level", "level": "warning"}))
    sub.send(json.dumps({"op": "subscribe", "topic": topic, "type": type_name}))
    sub.send(json.dumps({"op": "call_service", "service": "/rosapi/topics", "id": "ready"}))
    while '"service_response"' not in str(sub.recv(timeout=20)):
        pass  # the subscription is in place once the call is answered
    return sub


def _open(
    kind: str, port: int, topic: str, type_name: str, subscribers: int
) -> tuple[ClientConnection, list[ClientConnection]]:
    """A publisher and ``subscribers`` subscribers on ``topic`` (the relay: its group).

    The second subscriber, if any, is the slow reader (``SLOW_QUEUE``).
    """
    if kind == "rwt":
        subs = [_subscribe_rwt(port, topic, type_name, i == 1) for i in range(subscribers)]
        pub = _connect(f"ws://127.0.0.1:{port}")
        pub.send(json.dumps({"op": "advertise", "topic": topic, "type": type_name}))
        return pub, subs
    group = topic.strip("/")
    subs = [_connect(f"ws://127.0.0.1:{port}/sub/{group}", i == 1) for i in range(subscribers)]
    pub = _connect(f"ws://127.0.0.1:{port}/pub/{group}")
    for connection in (*subs, pub):
        assert connection.recv(timeout=20) == "ready"
    return pub, subs


def _slow_reader(sub: ClientConnection, period_s: float, stop: threading.Event) -> list[int]:
    """Read one message every ``period_s`` until ``stop``; the count read, in a list."""
    count = [0]

    def read() -> None:
        try:
            while not stop.is_set():
                sub.recv(timeout=IDLE_S)
                count[0] += 1
                time.sleep(period_s)
        except (TimeoutError, ConnectionClosed):
            pass

    threading.Thread(target=read, daemon=True).start()
    return count


def _burst(kind: str, port: int, frames: list[str], *, slow: bool = False) -> BurstResult:
    pub, subs = _open(kind, port, TOPIC, "std_msgs/String", 2 if slow else 1)
    sub = subs[0]
    stop = threading.Event()
    if slow:
        _slow_reader(subs[1], SLOW_PERIOD_S, stop)
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
    stop.set()
    for connection in (pub, *subs):
        connection.close()
    elapsed = max(last - start, 1e-9)
    return BurstResult(kind, len(frames), received, received / elapsed)


@dataclass(frozen=True)
class StreamResult:
    """A paced image stream with a slow reader: frames published, and what the bystander got.

    ``rate`` is the bystander's frames per second from the first publish to
    its last frame; ``publish_share`` that rate over the publish rate.
    """

    server: str
    sent: int
    bystander: int
    slow: int
    rate: float

    @property
    def publish_share(self) -> float:
        return self.rate / STREAM_HZ


def _image_frames(count: int) -> list[str]:
    pixels = base64.b64encode(bytes(range(256)) * 900).decode()  # 320x240 rgb8
    return [
        json.dumps(
            {
                "op": "publish",
                "topic": STREAM_TOPIC,
                "msg": {
                    "header": {"stamp": {"secs": i, "nsecs": 0}, "frame_id": "camera"},
                    "height": 240,
                    "width": 320,
                    "encoding": "rgb8",
                    "is_bigendian": 0,
                    "step": 960,
                    "data": pixels,
                },
            }
        )
        for i in range(count)
    ]


def _stream(kind: str, port: int, frames: list[str]) -> StreamResult:
    """Publish ``frames`` at 30 Hz (late ones at once) with a bystander and a slow reader."""
    pub, (bystander, slow) = _open(kind, port, STREAM_TOPIC, "sensor_msgs/Image", 2)
    stop = threading.Event()
    slow_count = _slow_reader(slow, STREAM_SLOW_PERIOD_S, stop)
    received = 0
    last = 0.0

    def read() -> None:
        nonlocal received, last
        try:
            while received < len(frames):
                message = bystander.recv(timeout=IDLE_S)
                if '"publish"' in str(message)[:40]:
                    received += 1
                    last = time.perf_counter()
        except (TimeoutError, ConnectionClosed):
            pass

    reader = threading.Thread(target=read)
    reader.start()
    start = time.perf_counter()
    for i, frame in enumerate(frames):
        time.sleep(max(0.0, start + i / STREAM_HZ - time.perf_counter()))
        pub.send(frame)
    reader.join()
    stop.set()
    for connection in (pub, bystander, slow):
        connection.close()
    elapsed = max(last - start, len(frames) / STREAM_HZ)  # the stream's own length at best
    return StreamResult(kind, len(frames), received, slow_count[0], received / elapsed)


def run_burst(count: int) -> dict[str, BurstResult]:
    """B19 on ``rwt serve`` and on the bare relay, one after the other; results by server."""
    frames = _frames(count)
    results: dict[str, BurstResult] = {}
    for kind in ("bare", "rwt"):
        with start_server(kind) as server:
            results[kind] = _burst(kind, server.port, frames)
    return results


def run_slow_reader(
    count: int, stream_frames: int, kinds: tuple[str, ...] = ("bare", "rwt")
) -> tuple[dict[str, BurstResult], dict[str, StreamResult]]:
    """B19's slow-reader variant on ``kinds`` (both servers): the burst and the image
    stream, by server."""
    frames, images = _frames(count), _image_frames(stream_frames)
    bursts: dict[str, BurstResult] = {}
    streams: dict[str, StreamResult] = {}
    for kind in kinds:
        with start_server(kind) as server:
            bursts[kind] = _burst(kind, server.port, frames, slow=True)
        with start_server(kind) as server:
            streams[kind] = _stream(kind, server.port, images)
    return bursts, streams


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=200_000, help="publishes to send")
    parser.add_argument("--smoke", action="store_true", help=f"{SMOKE_COUNT} messages")
    parser.add_argument(
        "--slow-reader", action="store_true", help="also run the variant with a slow reader"
    )
    args = parser.parse_args()
    count = SMOKE_COUNT if args.smoke else args.count
    results = run_burst(count)
    rwt, bare = results["rwt"], results["bare"]
    for result in (bare, rwt):
        print(json.dumps(asdict(result) | {"delivered_ratio": result.delivered_ratio}))
    print(
        f"B19 burst to one reading subscriber, {rwt.sent:,} x String 100 B over WebSocket: "
        f"rwt delivered {rwt.delivered:,}/{rwt.sent:,} ({100 * rwt.delivered_ratio:.1f} %) "
        f"at {rwt.rate:,.0f} msg/s; bare {bare.delivered:,}/{bare.sent:,} at "
        f"{bare.rate:,.0f} msg/s; ratio {rwt.rate / bare.rate:.2f}x"
    )
    if not args.slow_reader:
        return
    bursts, streams = run_slow_reader(count, SMOKE_STREAM_FRAMES if args.smoke else STREAM_FRAMES)
    for kind in ("bare", "rwt"):
        burst, stream = bursts[kind], streams[kind]
        print(json.dumps(asdict(burst) | {"delivered_ratio": burst.delivered_ratio}))
        print(json.dumps(asdict(stream) | {"publish_share": stream.publish_share}))
    burst, stream = bursts["rwt"], streams["rwt"]
    print(
        f"B19 with a slow reader present, rwt: the reading subscriber got "
        f"{burst.delivered:,}/{burst.sent:,} at {burst.rate:,.0f} msg/s, "
        f"{burst.rate / bursts['bare'].rate:.2f}x the bare relay with a slow reader "
        f"({burst.rate / bare.rate:.2f}x plain B19 bare); 30 Hz image stream: bystander "
        f"{stream.bystander}/{stream.sent} frames at {stream.rate:.1f} frames/s = "
        f"{100 * stream.publish_share:.0f} % of the publish rate (bare "
        f"{100 * streams['bare'].publish_share:.0f} %); the slow reader took {stream.slow}"
    )


if __name__ == "__main__":
    main()
