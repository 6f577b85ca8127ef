"""Throughput scenarios: B1 (1 -> 1), B2 (fan-out), B4 (large messages).

One publisher sends as fast as a window of undelivered messages allows, for a
fixed time; every subscriber must receive every message, byte for byte (or, for
cbor-raw, a frame whose serialized message ends with the published data).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import cbor2

from .. import msgs
from ..loadgen.engine import (
    ExactSubscriber,
    FrameBlock,
    GeneratorError,
    Subscriber,
    WindowPublisher,
    close_all,
    run_loop,
)
from ..loadgen.tail import TailStream, TailSubscriber
from ..loadgen.wire import as_served, client_frame, server_frame
from .common import Metrics, Run, server_figures, settle

__all__ = ["Stream", "stream_run"]


@dataclass(frozen=True)
class Stream:
    """What one throughput run sends.

    Attributes:
        topic: topic name.
        type_name: message type.
        make: publish op payload of sequence number ``i``.
        binary: the publisher sends binary (CBOR) frames.
        compression: the subscribers' ``compression``.
        period: distinct messages before the stream repeats.
        payload_bytes: bytes of message data per message, for MB/s.
    """

    topic: str
    type_name: str
    make: Callable[[int], bytes]
    binary: bool = False
    compression: str = "none"
    period: int = 4096
    payload_bytes: int = 0


def _subscribers(run: Run, stream: Stream, count: int) -> list[Subscriber]:
    setup = [msgs.subscribe(stream.topic, stream.type_name, stream.compression)]
    if run.kind == "rwt" and stream.compression == "cbor-raw":
        return _raw_subscribers(run, stream, setup, count)
    payloads = [as_served(run.kind, stream.make(i)) for i in range(stream.period)]
    block = b"".join(server_frame(p, binary=stream.binary) for p in payloads)
    frame_len = len(block) // stream.period
    if any(len(p) != len(payloads[0]) for p in payloads):
        raise ValueError("the frames of a stream must have one length")
    return [ExactSubscriber(run.port, run.kind, setup, block, frame_len) for _ in range(count)]


def _raw_subscribers(run: Run, stream: Stream, setup: list[bytes], count: int) -> list[Subscriber]:
    """cbor-raw: every frame must name the topic and end with the data of the next message.

    The CDR bytes are the last item of the frame's map and end with the image
    data, so the frame itself ends with it; ``TailSubscriber`` compares that
    tail in place for every frame, so the generator keeps pace with ten 4 MiB
    subscribers (count and content of every delivered message).
    """
    data = [cbor2.loads(stream.make(i))["msg"]["data"] for i in range(stream.period)]
    mark = cbor2.dumps(stream.topic)
    return [
        TailSubscriber(run.port, run.kind, setup, TailStream(lambda i: data[i % len(data)], mark))
        for _ in range(count)
    ]


def stream_run(
    run: Run, stream: Stream, *, subscribers: int, duration_s: float, window_bytes: int = 4 << 20
) -> Metrics:
    """One throughput run; returns msg/s, deliveries/s, MB/s and server figures."""
    subs = _subscribers(run, stream, subscribers)
    frames = [client_frame(stream.make(i), binary=stream.binary) for i in range(stream.period)]
    block = FrameBlock(b"".join(frames), len(frames[0]))
    window = max(2, min(2000, window_bytes // block.frame_len))
    pub = WindowPublisher(
        run.port,
        run.kind,
        [msgs.advertise(stream.topic, stream.type_name)],
        block,
        window=window,
        duration_s=duration_s * run.scale,
    )
    pub.watch = list(subs)
    try:
        before = run.server.stats()
        loop = run_loop(
            [pub],
            subs,
            done=lambda: pub.finished and all(s.received >= pub.sent for s in subs),
            limit_s=duration_s * run.scale + 30.0,
        )
        after = run.server.stats()
    finally:
        close_all([pub, *subs])
    for sub in subs:
        if sub.received != pub.sent:
            raise GeneratorError(f"a subscriber got {sub.received} of {pub.sent} messages")
    first = pub.first_s or 0.0
    window_s = max(s.last_s or first for s in subs) - first
    deliveries = pub.sent * subscribers
    figures = server_figures(before, after, loop, pub.sent, window_s)
    figures.update(
        {
            "msg_per_s": pub.sent / window_s,
            "deliveries_per_s": deliveries / window_s,
            "mb_per_s": deliveries * stream.payload_bytes / window_s / 1e6,
            "server_cpu_us_per_delivery": figures["server_cpu_us_per_msg"] / subscribers,
            "messages": pub.sent,
        }
    )
    settle()
    time.sleep(0)
    return figures
