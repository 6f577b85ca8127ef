"""Paced scenarios: B5 (images at 30 Hz), B6 (point clouds), B7 (latency), B9 (head of line).

Publishers send on a schedule and remember when each message left; subscribers
parse every frame, check it is the expected message and take its latency.
"""

from __future__ import annotations

from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import cbor2
import msgspec

from .. import msgs
from ..loadgen.engine import (
    ExactSubscriber,
    GeneratorError,
    ParsingSubscriber,
    RatePublisher,
    Subscriber,
    close_all,
    percentile_ms,
    run_loop,
)
from ..loadgen.wire import OP_BINARY, OP_TEXT, as_served, client_frame, server_frame
from .common import Metrics, Run, server_figures, settle

__all__ = ["LatencyTrack", "image_rate_run", "mixed_run", "topic_latency_run"]

_SEQ = msgs.SEQ_DIGITS


@dataclass
class LatencyTrack:
    """Latencies of one paced text topic whose messages carry ``"data":"<seq>..."``.

    The check compares each frame with the payload the publisher sent.
    """

    make: Callable[[int], bytes]
    marker: bytes = b'"data":"'
    kind: str = "rwt"
    """The server's kind: how it writes the payload (``as_served``)."""
    publisher: RatePublisher | None = None
    latencies_s: array[float] = field(default_factory=lambda: array("d"))
    """Seconds, in arrival order (an array: see ``RatePublisher.sent_at``)."""

    def seq_of(self, payload: bytes) -> int:
        start = payload.find(self.marker)
        if start < 0:
            raise GeneratorError(f"not a message of this topic: {payload[:80]!r}")
        start += len(self.marker)
        return int(payload[start : start + _SEQ])

    def check(self, payload: bytes, now: float) -> None:
        seq = self.seq_of(payload)
        if payload != as_served(self.kind, self.make(seq)):
            raise GeneratorError(f"wrong content for message {seq}: {payload[:80]!r}")
        assert self.publisher is not None
        self.latencies_s.append(now - self.publisher.sent_at[seq])


def _twist_marker_make(topic: str) -> tuple[bytes, Callable[[int], bytes]]:
    """Twist messages whose ``linear.x`` is ``1000000SS.5``: the seq is read from it."""

    def make(seq: int) -> bytes:
        return msgs.twist_publish(topic, seq)

    return b'"linear":{"x":1', make


class _TwistTrack(LatencyTrack):
    def seq_of(self, payload: bytes) -> int:
        start = payload.find(self.marker)
        if start < 0:
            raise GeneratorError(f"not a Twist of this topic: {payload[:80]!r}")
        start += len(self.marker)
        return int(payload[start : start + _SEQ])


def topic_latency_run(
    run: Run,
    *,
    subscribers: int,
    rate_hz: float,
    duration_s: float,
    type_name: str = "std_msgs/msg/String",
) -> Metrics:
    """B7: 100 B String at ``rate_hz`` to ``subscribers``; p50/p99 latency in ms."""
    topic = "/b7"
    tracks = [
        LatencyTrack(lambda i: msgs.string_publish(topic, i), kind=run.kind)
        for _ in range(subscribers)
    ]
    subs = [
        ParsingSubscriber(
            run.port,
            run.kind,
            [msgs.subscribe(topic, type_name)],
            lambda op, payload, now, t=t: t.check(payload, now),
        )
        for t in tracks
    ]
    pub = RatePublisher(
        run.port,
        run.kind,
        [msgs.advertise(topic, type_name)],
        lambda i: client_frame(msgs.string_publish(topic, i)),
        rate_hz=rate_hz,
        duration_s=duration_s * run.scale,
    )
    for t in tracks:
        t.publisher = pub
    return _finish(run, pub, subs, lambda: [x for t in tracks for x in t.latencies_s], pub.count)


def _finish(
    run: Run,
    pub: RatePublisher,
    subs: list[Subscriber],
    latencies: Sequence[float] | Callable[[], Sequence[float]],
    messages: int,
    others: list[RatePublisher] = (),  # type: ignore[assignment]
) -> Metrics:
    pubs = [pub, *others]
    try:
        before = run.server.stats()
        loop = run_loop(
            pubs,
            subs,
            done=lambda: (
                all(p.finished for p in pubs)
                and all(s.received >= _expected(s, pubs) for s in subs)
            ),
            limit_s=max(p.duration_s for p in pubs) + 30.0,
        )
        after = run.server.stats()
    finally:
        close_all([*pubs, *subs])
    values = latencies() if callable(latencies) else latencies
    figures = server_figures(before, after, loop, messages, loop.wall_s)
    figures.update(
        {
            "p50_ms": percentile_ms(values, 0.5),
            "p99_ms": percentile_ms(values, 0.99),
            "max_ms": percentile_ms(values, 1.0),
        }
    )
    settle()
    return figures


def _expected(sub: Subscriber, pubs: list[RatePublisher]) -> int:
    return getattr(sub, "expected", None) or sum(p.sent for p in pubs)


def image_rate_run(
    run: Run, *, binary: bool, subscribers: int, duration_s: float, rate_hz: float = 30.0
) -> Metrics:
    """B5: 640x480 rgb8 images at 30 Hz as JSON or CBOR; the slowest subscriber's Hz."""
    topic, type_name = "/b5", "sensor_msgs/msg/Image"
    period = 4
    if binary:
        payloads = [msgs.image_cbor(topic, i, 640, 480, "rgb8") for i in range(period)]
    else:
        payloads = [
            msgs.publish_json(topic, msgs.image_json_msg(i, 640, 480)) for i in range(period)
        ]
    block = b"".join(server_frame(p, binary=binary) for p in payloads)
    compression = "cbor" if binary else "none"
    subs = [
        ExactSubscriber(
            run.port,
            run.kind,
            [msgs.subscribe(topic, type_name, compression)],
            block,
            len(block) // period,
        )
        for _ in range(subscribers)
    ]
    frames = [client_frame(p, binary=binary) for p in payloads]
    pub = RatePublisher(
        run.port,
        run.kind,
        [msgs.advertise(topic, type_name)],
        lambda i: frames[i % period],
        rate_hz=rate_hz,
        duration_s=duration_s * run.scale,
    )
    figures = _finish(run, pub, subs, [], pub.count)
    rates = [
        (s.received - 1) / ((s.last_s or 0) - (s.first_s or 0))
        for s in subs
        if s.received > 1 and s.last_s != s.first_s
    ]
    for s in subs:
        if s.received != pub.sent:
            raise GeneratorError(f"a subscriber got {s.received} of {pub.sent} images")
    figures["delivered_hz"] = min(rates) if rates else float("nan")
    figures["mb_per_s"] = sum(len(p) for p in payloads) / period * rate_hz * subscribers / 1e6
    return figures


@dataclass
class _BigTopic:
    """A large binary topic beside a small one: counts and size checks of its frames."""

    size: int
    seen: int = 0

    def check(self, payload: bytes) -> None:
        if abs(len(payload) - self.size) > 4096:
            raise GeneratorError(f"large message of {len(payload)} bytes, expected ~{self.size}")
        self.seen += 1


def mixed_run(
    run: Run,
    *,
    big: Callable[[int], bytes],
    big_binary: bool,
    big_type: str,
    big_compression: str,
    big_hz: float,
    duration_s: float,
    sample: Callable[[bytes, int], bool] | None = None,
    twist_hz: float = 100.0,
) -> Metrics:
    """B6/B9: a Twist stream (100 Hz) and a large topic to one subscriber connection.

    Returns the Twist latencies and the server CPU per large message (ms), all
    of the server's CPU charged to the large messages.
    """
    small_topic, big_topic = "/twist", "/big"
    marker, make = _twist_marker_make(small_topic)
    track = _TwistTrack(make, marker)
    expected_big = big(0)
    bigs = _BigTopic(len(expected_big))

    def check(opcode: int, payload: bytes, now: float) -> None:
        if opcode == OP_TEXT and payload.startswith(b'{"op":"publish","topic":"/twist"'):
            track.check(payload, now)
        elif (opcode == OP_BINARY) == (big_compression != "none"):
            bigs.check(payload)
            if sample is not None and not sample(payload, bigs.seen - 1):
                raise GeneratorError(f"wrong large message {bigs.seen - 1}")
        else:
            raise GeneratorError(f"unexpected frame {payload[:80]!r}")

    setup = [
        msgs.subscribe(small_topic, "geometry_msgs/msg/Twist"),
        msgs.subscribe(big_topic, big_type, big_compression),
    ]
    sub = ParsingSubscriber(run.port, run.kind, setup, check)
    duration = duration_s * run.scale
    small_pub = RatePublisher(
        run.port,
        run.kind,
        [msgs.advertise(small_topic, "geometry_msgs/msg/Twist")],
        lambda i: client_frame(make(i)),
        rate_hz=twist_hz,
        duration_s=duration,
    )
    track.publisher = small_pub
    big_frames = [client_frame(big(i), binary=big_binary) for i in range(2)]
    big_pub = RatePublisher(
        run.port,
        run.kind,
        [msgs.advertise(big_topic, big_type)],
        lambda i: big_frames[i % 2],
        rate_hz=big_hz,
        duration_s=duration,
        start_delay_s=0.05,
    )
    figures = _finish(run, small_pub, [sub], track.latencies_s, big_pub.count, [big_pub])
    if bigs.seen != big_pub.sent:
        raise GeneratorError(f"got {bigs.seen} of {big_pub.sent} large messages")
    figures["server_cpu_ms_per_big"] = figures.pop("server_cpu_us_per_msg") / 1e3
    return figures


def cloud_sample(binary: bool) -> Callable[[bytes, int], bool]:
    """B6: a delivered cloud's data must start with its sequence number."""

    def sample(payload: bytes, index: int) -> bool:
        tag = f"{index % 2:0{_SEQ}d}".encode()
        if binary:
            data = cbor2.loads(payload)["msg"]["data"]
            return bytes(data[:_SEQ]) == tag
        msg = msgspec.json.decode(payload)["msg"]
        import base64  # noqa: PLC0415

        return base64.b64decode(msg["data"][:12])[:_SEQ] == tag

    return sample
