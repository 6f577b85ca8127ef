"""Z2 with the suite's raw-socket load generator: 1 publisher -> N subscribers on one port.

``scaleout``'s first Z2 generator reads every subscriber with ``websockets`` and
costs 21-37 us of its own CPU per delivery, so on 2 cores it, not the server,
bounds the figure. This one uses ``benchmarks.loadgen`` (non-blocking sockets,
one ``selectors`` loop, frames cut by hand: a few us per delivery), as B2 does.

The steps, each for one server URL (a single ``rwt serve`` or ``--workers 2``):

1. ``subscribers`` peers subscribe to ``/fan`` and one advertises it; each
   passes the loadgen barrier (a ``/rosapi/get_time`` reply on its connection).
2. Probes: the publisher sends a ``probe`` message every 50 ms until every
   subscriber got one. With ``--workers`` a subscription on the other worker is
   known to the publisher's worker only once Zenoh's discovery has run, which the
   barrier does not wait for.
3. The timed burst: a window publisher sends 100 B ``std_msgs/String`` messages
   for ``duration_s``, never more than ``window`` ahead of the slowest
   subscriber (so no server drops anything under D24), and every subscriber
   counts the timed ones (probes still in flight are told apart by content).

The figure is deliveries per second from the first timed send to the last
delivery, with the generator's own CPU share beside it.
"""

from __future__ import annotations

import selectors
import time
from collections.abc import Callable

from . import msgs
from .loadgen.engine import (
    FrameBlock,
    GeneratorError,
    Subscriber,
    WindowPublisher,
    close_all,
    run_loop,
)
from .loadgen.wire import FrameReader, client_frame

__all__ = ["FanOut", "fan_out_raw"]

TOPIC = "/fan"
STRING = "std_msgs/msg/String"
PROBE_EVERY_S = 0.05
DISCOVERY_S = 120.0


class CountingSubscriber(Subscriber):
    """Counts the timed messages on ``/fan``; notes whether a probe came."""

    def __init__(self, port: int, topic: str = TOPIC) -> None:
        super().__init__(port, "rwt", [msgs.subscribe(topic, STRING)])
        self.reader = FrameReader()
        self.probed = False
        self.marker = b'"topic":"' + topic.encode() + b'"'

    def feed(self, data: bytes, now: float) -> None:
        for _, payload in self.reader.feed(data):
            if b'"data":"probe"' in payload:
                self.probed = True
            elif self.marker in payload:
                if self.first_s is None:
                    self.first_s = now
                self.last_s = now
                self.received += 1
            else:
                raise GeneratorError(f"unexpected frame {payload[:120]!r}")


def _probe(pub: WindowPublisher, subs: list[CountingSubscriber], topic: str = TOPIC) -> None:
    """Send probes on ``topic`` until every subscriber got one (step 2)."""
    probe = client_frame(msgs.publish_json(topic, b'{"data":"probe"}'))
    sel = selectors.DefaultSelector()
    for sub in subs:
        sub.start(time.perf_counter())
        sel.register(sub.sock, selectors.EVENT_READ, sub)
    deadline = time.monotonic() + DISCOVERY_S
    try:
        while not all(sub.probed for sub in subs):
            if time.monotonic() > deadline:
                missing = sum(not sub.probed for sub in subs)
                raise GeneratorError(f"{missing} subscribers never got a probe")
            pub.sock.setblocking(True)
            pub.sock.sendall(probe)
            pub.sock.setblocking(False)
            until = time.monotonic() + PROBE_EVERY_S
            while (left := until - time.monotonic()) > 0:
                for key, _ in sel.select(left):
                    key.data.readable(time.perf_counter())
    finally:
        sel.close()


def fan_out_raw(
    port: int,
    subscribers: int,
    duration_s: float,
    *,
    window: int = 512,
    on_timed: Callable[[], None] | None = None,
) -> dict[str, float]:
    """Deliveries/s of a window-paced 100 B stream to ``subscribers`` clients on ``port``.

    ``on_timed`` is called once, right before the timed burst (after the
    connections, subscriptions and probes of steps 1 and 2).

    Returns:
        ``deliveries_per_s``, ``delivered``, ``sent`` (messages), ``expected``
        (sent x subscribers), ``generator_cpu_share`` (of one core, while timed)
        and ``generator_cpu_us_per_delivery``.

    Raises:
        GeneratorError: a subscriber never got a probe, a frame was unexpected,
            or the burst did not complete.
    """
    subs = [CountingSubscriber(port) for _ in range(subscribers)]
    frames = [client_frame(msgs.string_publish(TOPIC, i)) for i in range(256)]
    pub = WindowPublisher(
        port,
        "rwt",
        [msgs.advertise(TOPIC, STRING)],
        FrameBlock(b"".join(frames), len(frames[0])),
        window=window,
        duration_s=duration_s,
    )
    pub.watch = list(subs)
    try:
        _probe(pub, subs)
        time.sleep(0.5)  # probes in flight land before the timed burst
        for sub in subs:
            sub.first_s = sub.last_s = None
            sub.received = 0
        if on_timed is not None:
            on_timed()
        loop = run_loop(
            [pub],
            list(subs),
            done=lambda: pub.finished and all(s.received >= pub.sent for s in subs),
            limit_s=duration_s + 60.0,
        )
    finally:
        close_all([pub, *subs])
    delivered = sum(sub.received for sub in subs)
    elapsed = max(s.last_s or 0.0 for s in subs) - (pub.first_s or 0.0)
    return {
        "deliveries_per_s": delivered / elapsed,
        "delivered": delivered,
        "sent": pub.sent,
        "expected": pub.sent * subscribers,
        "generator_cpu_share": loop.generator_cpu_s / loop.wall_s,
        "generator_cpu_us_per_delivery": loop.generator_cpu_s / max(delivered, 1) * 1e6,
    }


class FanOut:
    """One publisher and ``subscribers`` subscribers of ``topic`` on ``port``, kept connected.

    Raises:
        GeneratorError: a subscriber is never reached by a probe.
    """

    def __init__(self, port: int, subscribers: int = 100, topic: str = TOPIC) -> None:
        self.subs = [CountingSubscriber(port, topic) for _ in range(subscribers)]
        frames = [client_frame(msgs.string_publish(topic, i)) for i in range(256)]
        self.pub = WindowPublisher(
            port,
            "rwt",
            [msgs.advertise(topic, STRING)],
            FrameBlock(b"".join(frames), len(frames[0])),
            window=512,
            duration_s=0.0,
        )
        self.pub.watch = list(self.subs)
        _probe(self.pub, self.subs, topic)
        time.sleep(0.5)  # probes in flight land first

    def burst(
        self,
        duration_s: float,
        pid: int,
        cpu_ns: Callable[[int], int],
        rate_hz: float | None = None,
    ) -> tuple[int, int]:
        """Publish for ``duration_s`` and wait for every delivery (none may be dropped).

        ``rate_hz``: at most that many messages a second (else as the window allows).

        Returns:
            (deliveries, ``cpu_ns(pid)`` after less before: the server's CPU meanwhile).
        """
        pub = self.pub
        pub.duration_s = duration_s
        pub.rate_hz = rate_hz
        pub.first_s = pub.stop_s = None
        pub.sent = 0
        for sub in self.subs:
            sub.first_s = sub.last_s = None
            sub.received = 0
        before = cpu_ns(pid)
        run_loop(
            [pub],
            list(self.subs),
            done=lambda: pub.finished and all(s.received >= pub.sent for s in self.subs),
            limit_s=duration_s + 60.0,
        )
        return sum(s.received for s in self.subs), cpu_ns(pid) - before

    def close(self) -> None:
        close_all([self.pub, *self.subs])
