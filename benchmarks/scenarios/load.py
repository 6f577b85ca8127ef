"""Load-shape scenarios: B3 (many topics), B8 (slow consumer), B10 (churn), B11 (idle)."""

from __future__ import annotations

import selectors
import time
from dataclasses import dataclass

from .. import msgs
from ..loadgen.engine import (
    ExactSubscriber,
    FrameBlock,
    GeneratorError,
    LoopResult,
    ParsingSubscriber,
    Peer,
    RatePublisher,
    WindowPublisher,
    close_all,
    run_loop,
)
from ..loadgen.wire import FrameReader, client_frame, server_frame
from ..servers import ProcStats
from .common import Metrics, Run, server_figures, settle

__all__ = ["churn_run", "idle_run", "slow_consumer_run", "topics_run"]

_STRING = "std_msgs/msg/String"
_REPEAT = 64  # B3: messages per topic before a publisher's frames repeat


def topics_run(run: Run, *, publishers: int, topics_each: int, duration_s: float) -> Metrics:
    """B3: ``publishers`` x ``topics_each`` topics -> one subscriber of all.

    Each publisher cycles through its topics; the subscriber checks every frame
    against the message its topic should carry next. Fairness is the least
    over the most messages delivered per topic.
    """
    names = [f"/b3_{p:02d}_{t:03d}" for p in range(publishers) for t in range(topics_each)]
    counts = dict.fromkeys(names, 0)
    per_pub = [0] * publishers

    def check(opcode: int, payload: bytes, now: float) -> None:
        topic = payload[25:35].decode()
        seq = counts.get(topic)
        if seq is None or payload != msgs.string_publish(topic, seq % _REPEAT):
            raise GeneratorError(f"unexpected or out-of-order message {payload[:70]!r}")
        counts[topic] = seq + 1
        per_pub[int(topic[4:6])] += 1

    setup = [msgs.subscribe(n, _STRING) for n in names] if run.kind == "rwt" else []
    sub = ParsingSubscriber(run.port, run.kind, setup, check)
    pubs = []
    for p in range(publishers):
        mine = names[p * topics_each : (p + 1) * topics_each]
        # message i goes to topic i % topics_each with that topic's i // topics_each-th seq
        frames = [
            client_frame(msgs.string_publish(mine[i % topics_each], i // topics_each))
            for i in range(topics_each * _REPEAT)
        ]
        pub = WindowPublisher(
            run.port,
            run.kind,
            [msgs.advertise(n, _STRING) for n in mine] if run.kind == "rwt" else [],
            FrameBlock(b"".join(frames), len(frames[0])),
            window=200,
            duration_s=duration_s * run.scale,
        )
        pub.delivered = lambda p=p: per_pub[p]
        pubs.append(pub)
    try:
        before = run.server.stats()
        loop = run_loop(
            pubs,
            [sub],
            done=lambda: (
                all(p.finished for p in pubs) and sub.received >= sum(p.sent for p in pubs)
            ),
            limit_s=duration_s * run.scale + 30.0,
        )
        after = run.server.stats()
    finally:
        close_all([*pubs, sub])
    total = sum(p.sent for p in pubs)
    window_s = (sub.last_s or 0) - min(p.first_s or 0 for p in pubs)
    figures = server_figures(before, after, loop, total, window_s)
    figures["msg_per_s"] = total / window_s
    figures["fairness"] = min(counts.values()) / max(*counts.values(), 1)
    settle()
    return figures


def slow_consumer_run(run: Run, *, readers: int, duration_s: float, size: int = 1000) -> Metrics:
    """B8: the readers' rate with and without one stalled subscriber, and the memory cost.

    Phase 1: ``readers`` + 1 reading subscribers; phase 2: ``readers`` reading
    and one that never reads (small receive buffer). The publisher's window
    follows the readers only. Returns the rate ratio, the server's RSS growth
    during phase 2 and the messages the stalled client never got.
    """
    topic = "/b8"
    payloads = [msgs.string_publish(topic, i, size) for i in range(1024)]
    block = b"".join(server_frame(p) for p in payloads)
    cframes = [client_frame(p) for p in payloads]
    stream = _B8Stream(
        topic, block, len(block) // len(payloads), FrameBlock(b"".join(cframes), len(cframes[0]))
    )
    rate_all, _ = _b8_phase(run, stream, readers, duration_s, stalled=False)
    rate_one, phase = _b8_phase(run, stream, readers, duration_s, stalled=True)
    figures = server_figures(phase.before, phase.after, phase.loop, phase.sent, phase.loop.wall_s)
    figures.update(
        {
            "rate_ratio": rate_one / rate_all,
            "msg_per_s_all_reading": rate_all,
            "msg_per_s_one_stalled": rate_one,
            "rss_growth_mb": (phase.after.rss_bytes - phase.before.rss_bytes) / 1e6,
            "undelivered": float(phase.undelivered),
        }
    )
    settle(0.2)
    return figures


@dataclass(frozen=True)
class _B8Stream:
    topic: str
    block: bytes
    frame_len: int
    client: FrameBlock


@dataclass(frozen=True)
class _Phase:
    before: ProcStats
    after: ProcStats
    loop: LoopResult
    sent: int
    undelivered: int


def _b8_phase(
    run: Run, stream: _B8Stream, readers: int, duration_s: float, *, stalled: bool
) -> tuple[float, _Phase]:
    setup = [msgs.subscribe(stream.topic, _STRING)]
    subs = [
        ExactSubscriber(run.port, run.kind, setup, stream.block, stream.frame_len)
        for _ in range(readers)
    ]
    slow = ExactSubscriber(run.port, run.kind, setup, stream.block, stream.frame_len, rcvbuf=16384)
    slow.stalled = stalled
    pub = WindowPublisher(
        run.port,
        run.kind,
        [msgs.advertise(stream.topic, _STRING)],
        stream.client,
        window=500,
        duration_s=duration_s * run.scale,
    )
    pub.watch = subs if stalled else [*subs, slow]
    undelivered = 0
    try:
        before = run.server.stats()
        loop = run_loop(
            [pub],
            [*subs, slow],
            done=lambda: pub.finished and all(s.received >= pub.sent for s in pub.watch),
            limit_s=duration_s * run.scale + 30.0,
        )
        after = run.server.stats()
        if stalled:
            undelivered = pub.sent - _drain(slow, pub.sent)
    finally:
        close_all([pub, *subs, slow])
    rate = pub.sent / (max(s.last_s or 0 for s in subs) - (pub.first_s or 0))
    return rate, _Phase(before, after, loop, pub.sent, undelivered)


def _drain(sub: ExactSubscriber, sent: int, quiet_s: float = 0.5) -> int:
    """Read what the stalled client can still get; return how many messages it received."""
    sub.sock.setblocking(True)
    sub.sock.settimeout(quiet_s)
    sub.stalled = False
    total = 0
    try:
        while sub.received < sent:
            data = sub.sock.recv(262144)
            if not data:
                break
            total += len(data)
            _count_frames(sub, data)
    except (TimeoutError, OSError):
        pass
    return sub.received


def _count_frames(sub: ExactSubscriber, data: bytes) -> None:
    """Frames after a drop no longer match the block: count them by parsing instead."""
    reader = getattr(sub, "_drain_reader", None)
    if reader is None:
        reader = FrameReader()
        sub._drain_reader = reader  # type: ignore[attr-defined]
    sub.received += len(reader.feed(data))


def churn_run(run: Run, *, clients: int, churners: int, rounds: int, spread_s: float) -> Metrics:
    """B10: ``clients`` connect and subscribe within ``spread_s``; ``churners`` reconnect.

    A publisher sends at 100 Hz throughout. Each connection measures the time
    from starting to connect to its first topic message; returns the worst.
    """
    topic = "/b10"
    pub = RatePublisher(
        run.port,
        run.kind,
        [msgs.advertise(topic, _STRING)],
        lambda i: client_frame(msgs.string_publish(topic, i % 100000)),
        rate_hz=100.0,
        duration_s=30.0,
    )
    waits: list[float] = []
    sel = selectors.DefaultSelector()
    sel.register(pub.sock, selectors.EVENT_READ, pub)
    pending: dict[int, tuple[Peer, float, FrameReader, int]] = {}
    plan = [(i * spread_s / clients, i < churners) for i in range(clients)]
    start = time.perf_counter()
    remaining_rounds = {i: rounds if churn else 0 for i, (_, churn) in enumerate(plan)}
    todo = [(start + t, i) for i, (t, _) in enumerate(plan)]
    peers: list[Peer] = [pub]
    cpu_before = run.server.stats()
    try:
        while todo or pending:
            now = time.perf_counter()
            if now - start > 20.0:
                raise GeneratorError(f"{len(pending) + len(todo)} connections never got a message")
            pub.push(now)
            for due, index in [x for x in todo if x[0] <= now]:
                todo.remove((due, index))
                t0 = time.perf_counter()
                peer = Peer(run.port, run.kind, [msgs.subscribe(topic, _STRING)], receives=True)
                peers.append(peer)
                pending[peer.fileno()] = (peer, t0, FrameReader(), index)
                sel.register(peer.sock, selectors.EVENT_READ, peer)
                if peer.leftover:
                    _first(peer, peer.leftover, pending, waits, remaining_rounds, todo, sel)
            for key, _ in sel.select(0.005):
                peer = key.data
                if peer is pub:
                    pub.readable(now)
                    continue
                try:
                    data = peer.sock.recv(65536)
                except BlockingIOError:
                    continue
                if not data:
                    raise GeneratorError("server closed a churn connection")
                _first(peer, data, pending, waits, remaining_rounds, todo, sel)
    finally:
        sel.close()
        close_all(peers)
    after = run.server.stats()
    figures = {
        "max_first_message_s": max(waits),
        "p50_first_message_s": sorted(waits)[len(waits) // 2],
        "connections": float(len(waits)),
        "server_rss_mb": after.rss_bytes / 1e6,
        "server_cpu_s": after.cpu_s - cpu_before.cpu_s,
    }
    settle(0.2)
    return figures


def _first(
    peer: Peer,
    data: bytes,
    pending: dict[int, tuple[Peer, float, FrameReader, int]],
    waits: list[float],
    remaining_rounds: dict[int, int],
    todo: list[tuple[float, int]],
    sel: selectors.BaseSelector,
) -> None:
    entry = pending.get(peer.fileno())
    if entry is None:
        return
    _, t0, reader, index = entry
    frames = reader.feed(data)
    if not frames:
        return
    if not frames[0][1].startswith(b'{"op":"publish","topic":"/b10"'):
        raise GeneratorError(f"unexpected first message {frames[0][1][:60]!r}")
    waits.append(time.perf_counter() - t0)
    del pending[peer.fileno()]
    if remaining_rounds[index] > 0:  # churn: drop it at once and come back
        remaining_rounds[index] -= 1
        sel.unregister(peer.sock)
        peer.sock.close()
        todo.append((time.perf_counter(), index))


def idle_run(run: Run, *, connections: int, topics: int, window_s: float) -> Metrics:
    """B11: base memory, memory per idle connection and idle CPU.

    One client advertises ``topics`` topics (rwt only); then ``connections``
    clients connect and stay idle; CPU is read over ``window_s``.
    """
    time.sleep(0.5)
    base = run.server.stats()
    advertiser = Peer(
        run.port,
        run.kind,
        [msgs.advertise(f"/b11_{i:04d}", _STRING) for i in range(topics)]
        if run.kind == "rwt"
        else [],
        receives=False,
    )
    with_topics = run.server.stats()
    idle = [Peer(run.port, run.kind, [], receives=True) for _ in range(connections)]
    time.sleep(0.5)
    loaded = run.server.stats()
    time.sleep(window_s * run.scale)
    end = run.server.stats()
    close_all([advertiser, *idle])
    settle(0.2)
    return {
        "base_rss_mb": base.rss_bytes / 1e6,
        "topics_rss_mb": (with_topics.rss_bytes - base.rss_bytes) / 1e6,
        "kb_per_connection": (loaded.rss_bytes - with_topics.rss_bytes) / connections / 1e3,
        "idle_cpu_pct": 100.0 * (end.cpu_s - loaded.cpu_s) / (window_s * run.scale),
        "server_rss_mb": end.rss_bytes / 1e6,
    }
