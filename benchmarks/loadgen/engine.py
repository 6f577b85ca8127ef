"""The load generator's event loop: publishers and subscribers on raw sockets.

One process, one ``selectors`` loop, non-blocking sockets. Publishers write
pre-built frames, either as fast as a window of unacknowledged messages allows
(throughput) or on a schedule (latency, rates); subscribers check what arrives.
Each peer first passes a barrier: it sends its setup ops (rwt: subscribe or
advertise, then a ``call_service`` to ``/rosapi/get_time``) and waits for one
frame (the service reply; the bare relay's ``ready``), so no message is
published before every subscription exists.

Every delivered message is checked ("a fast wrong server cannot pass"):
``ExactSubscriber`` compares the whole byte stream with the expected frames,
``ParsingSubscriber`` hands each frame to a check of the scenario's.
"""

from __future__ import annotations

import contextlib
import itertools
import selectors
import socket
import time
from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from .wire import FrameReader, client_frame, connect

__all__ = [
    "BARRIER",
    "ExactSubscriber",
    "FrameBlock",
    "FrameCheck",
    "GeneratorError",
    "LoopResult",
    "ParsingSubscriber",
    "Peer",
    "Publisher",
    "RatePublisher",
    "Subscriber",
    "WindowPublisher",
    "close_all",
    "percentile_ms",
    "run_loop",
]

BARRIER = b'{"op":"call_service","service":"/rosapi/get_time","id":"barrier"}'
_RECV = 262144
_BATCH_BYTES = 65536


class GeneratorError(Exception):
    """A peer saw something wrong (wrong bytes, lost messages, a status frame)."""


class Peer:
    """One connection: connect, send setup ops, wait for the barrier frame.

    Args:
        port: the server's port.
        kind: ``bare`` (connects to ``/sub`` when ``receives``), ``rwt`` or
            ``rosbridge`` (rosbridge_suite, benchmarks/peer.py).
        setup: payloads of the setup ops (not for the bare relay; the barrier is appended).
        receives: whether this peer receives topic data (bare relay's ``/sub``).
        rcvbuf: the socket's receive buffer in bytes, else the system's default.
        group: the bare relay's routing group (a topic); rwt ignores the path.
    """

    def __init__(
        self,
        port: int,
        kind: str,
        setup: Sequence[bytes],
        *,
        receives: bool,
        rcvbuf: int | None = None,
        group: str = "",
    ) -> None:
        path = f"/{'sub' if receives else 'pub'}/{group}"
        self.sock, rest = connect(port, path, rcvbuf=rcvbuf)
        self.kind = kind
        if kind != "bare":
            self.sock.sendall(b"".join(client_frame(p) for p in [*setup, BARRIER]))
        self.leftover = self._barrier(rest)
        self.sock.setblocking(False)

    def _barrier(self, rest: bytes) -> bytes:
        reader = FrameReader()
        frames = reader.feed(rest)
        while not frames:
            chunk = self.sock.recv(_RECV)
            if not chunk:
                raise GeneratorError("closed before the barrier")
            frames = reader.feed(chunk)
        payload = frames[0][1]
        expected = b"ready" if self.kind == "bare" else b'"id":"barrier"'
        if expected not in payload:
            raise GeneratorError(f"unexpected first frame {payload[:120]!r}")
        extra = b"".join(frame_bytes(op, p) for op, p in frames[1:])
        return extra + reader.take_rest()

    def fileno(self) -> int:
        return self.sock.fileno()

    def readable(self, now: float) -> None:
        """Data on a peer that expects none: a status or error frame."""
        data = self._recv()
        if data:
            raise GeneratorError(f"unexpected data on a publisher: {data[:160]!r}")

    def _recv(self) -> bytes:
        try:
            data = self.sock.recv(_RECV)
        except BlockingIOError:
            return b""
        if not data:
            raise GeneratorError("server closed the connection")
        return data

    def close(self) -> None:
        self.sock.close()


def frame_bytes(opcode: int, payload: bytes) -> bytes:
    """Re-serialise a parsed server frame (for bytes read past the barrier)."""
    from .wire import server_frame  # noqa: PLC0415

    return server_frame(payload, binary=opcode == 2)


class Subscriber(Peer):
    """A receiving peer: counts messages and records first and last arrival."""

    def __init__(
        self,
        port: int,
        kind: str,
        setup: Sequence[bytes],
        *,
        rcvbuf: int | None = None,
        group: str = "",
    ) -> None:
        super().__init__(port, kind, setup, receives=True, rcvbuf=rcvbuf, group=group)
        self.received = 0
        self.first_s: float | None = None
        self.last_s: float | None = None
        self.stalled = False

    def start(self, now: float) -> None:
        """Feed what came with the barrier."""
        if self.leftover:
            self.feed(self.leftover, now)
            self.leftover = b""

    def readable(self, now: float) -> None:
        data = self._recv()
        if data:
            self.feed(data, now)

    def feed(self, data: bytes, now: float) -> None:
        raise NotImplementedError


class ExactSubscriber(Subscriber):
    """Compares the received stream with the expected one, byte for byte.

    The expected stream repeats ``block`` (``len(block) // frame_len`` frames of
    ``frame_len`` bytes each); any difference is an error, so content, order and
    count are all checked at memcmp speed.
    """

    def __init__(
        self,
        port: int,
        kind: str,
        setup: Sequence[bytes],
        block: bytes,
        frame_len: int,
        *,
        rcvbuf: int | None = None,
        group: str = "",
    ) -> None:
        super().__init__(port, kind, setup, rcvbuf=rcvbuf, group=group)
        self.block = block
        self.frame_len = frame_len
        self.pos = 0

    def feed(self, data: bytes, now: float) -> None:
        if self.first_s is None:
            self.first_s = now
        self.last_s = now
        block = self.block
        size = len(block)
        offset = self.pos % size
        start = 0
        while start < len(data):
            take = min(len(data) - start, size - offset)
            got = data[start : start + take] if start or take < len(data) else data
            want = block[offset : offset + take]
            if got != want:
                index = self.pos + _first_diff(got, want)
                raise GeneratorError(
                    f"wrong bytes at message {index // self.frame_len}"
                    f" (offset {index % self.frame_len}): got {got[:80]!r}"
                )
            self.pos += take
            start += take
            offset = 0
        self.received = self.pos // self.frame_len


def _first_diff(got: bytes, want: bytes) -> int:
    for i, (a, b) in enumerate(zip(got, want, strict=False)):
        if a != b:
            return i
    return min(len(got), len(want))


FrameCheck = Callable[[int, bytes, float], None]
"""Checks one delivered frame: (opcode, payload, arrival time); raises GeneratorError."""


class ParsingSubscriber(Subscriber):
    """Cuts the stream into frames and hands each to ``check``."""

    def __init__(self, port: int, kind: str, setup: Sequence[bytes], check: FrameCheck) -> None:
        super().__init__(port, kind, setup)
        self.reader = FrameReader()
        self.check = check

    def feed(self, data: bytes, now: float) -> None:
        if self.first_s is None:
            self.first_s = now
        self.last_s = now
        for opcode, payload in self.reader.feed(data):
            self.check(opcode, payload, now)
            self.received += 1


class Publisher(Peer):
    """A sending peer; subclasses decide when to write."""

    def __init__(
        self,
        port: int,
        kind: str,
        setup: Sequence[bytes],
        *,
        receives: bool = False,
        group: str = "",
    ) -> None:
        super().__init__(port, kind, setup, receives=receives, group=group)
        self.sent = 0
        self.pending = memoryview(b"")
        self.first_s: float | None = None

    @property
    def wants_write(self) -> bool:
        return bool(self.pending)

    def writable(self) -> None:
        self._write()

    def _write(self) -> None:
        if not self.pending:
            return
        try:
            n = self.sock.send(self.pending)
        except BlockingIOError:
            return
        self.pending = self.pending[n:]

    def push(self, now: float) -> None:
        raise NotImplementedError

    def next_due(self, now: float) -> float | None:
        """Seconds until this publisher next wants to send, or None."""
        return None

    @property
    def finished(self) -> bool:
        raise NotImplementedError


@dataclass
class FrameBlock:
    """The periodic client stream of a publisher: ``count`` frames of equal length."""

    data: bytes
    frame_len: int

    @property
    def count(self) -> int:
        return len(self.data) // self.frame_len


class WindowPublisher(Publisher):
    """Sends as fast as a window of undelivered messages allows, for ``duration_s``.

    The window is measured against the slowest of ``watch`` (the subscribers
    whose rate is measured), so neither server's buffers grow without bound
    and nothing is dropped in a throughput run. With ``rate_hz`` set it also
    sends no faster than that many messages a second (a paced load).
    """

    def __init__(
        self,
        port: int,
        kind: str,
        setup: Sequence[bytes],
        block: FrameBlock,
        *,
        window: int,
        duration_s: float,
    ) -> None:
        super().__init__(port, kind, setup)
        self.block = block
        self.window = window
        self.duration_s = duration_s
        self.watch: list[Subscriber] = []
        self.stop_s: float | None = None
        self.rate_hz: float | None = None
        self.delivered: Callable[[], int] = lambda: min(
            (s.received for s in self.watch), default=self.sent
        )

    def push(self, now: float) -> None:
        if self.pending:
            self._write()
            if self.pending:
                return
        if self.first_s is None:
            self.first_s = now
            self.stop_s = now + self.duration_s
        if self.stop_s is not None and now >= self.stop_s:
            return
        room = self.window - (self.sent - self.delivered())
        limit = max(1, _BATCH_BYTES // self.block.frame_len)
        count = min(room, limit)
        if self.rate_hz is not None:  # the messages due by now, the first at once
            count = min(count, int((now - self.first_s) * self.rate_hz) + 1 - self.sent)
        if count <= 0:
            return
        start = self.sent % self.block.count
        count = min(count, self.block.count - start)
        flen = self.block.frame_len
        self.pending = memoryview(self.block.data)[start * flen : (start + count) * flen]
        self.sent += count
        self._write()

    def next_due(self, now: float) -> float | None:
        if self.rate_hz is None or self.first_s is None or self.stop_s is None:
            return None
        if now >= self.stop_s:
            return None
        return max(0.0, self.first_s + self.sent / self.rate_hz - now)

    @property
    def finished(self) -> bool:
        return self.stop_s is not None and not self.pending and time.perf_counter() >= self.stop_s


class RatePublisher(Publisher):
    """Sends ``make(i)`` at ``rate_hz`` for ``duration_s``; remembers each send time."""

    def __init__(
        self,
        port: int,
        kind: str,
        setup: Sequence[bytes],
        make: Callable[[int], bytes],
        *,
        rate_hz: float,
        duration_s: float,
        start_delay_s: float = 0.0,
        group: str = "",
    ) -> None:
        super().__init__(port, kind, setup, group=group)
        self.make = make
        self.period_s = 1.0 / rate_hz
        self.duration_s = duration_s
        self.start_delay_s = start_delay_s
        self.count = max(1, round(duration_s * rate_hz))
        # One float per message for hours at tens of kHz: an array holds them as
        # 8 bytes each. A list of float objects grew the generator by 130 MB a
        # minute in B15, and its full collections (walking every float) paused
        # it for 0.3 s and more, long enough for the server to drop frames.
        self.sent_at = array("d")
        self.frames = [make(i) for i in range(min(self.count, 64))] if self.count <= 64 else None
        self.start_s: float | None = None

    def push(self, now: float) -> None:
        if self.pending:
            self._write()
            if self.pending:
                return
        if self.start_s is None:
            self.start_s = now + self.start_delay_s
        # Every message due by now goes out in one write: at tens of kHz a send
        # per message made the generator, not the server, the limit (B15).
        due: list[bytes] = []
        while self.sent + len(due) < self.count and now >= (
            self.start_s + (self.sent + len(due)) * self.period_s
        ):
            due.append(self.make(self.sent + len(due)))
        if not due:
            return
        if self.first_s is None:
            self.first_s = now
        self.sent_at.extend(itertools.repeat(time.perf_counter(), len(due)))
        self.sent += len(due)
        self.pending = memoryview(due[0] if len(due) == 1 else b"".join(due))
        self._write()

    def next_due(self, now: float) -> float | None:
        if self.sent >= self.count or self.start_s is None:
            return None
        return max(0.0, self.start_s + self.sent * self.period_s - now)

    @property
    def finished(self) -> bool:
        return self.sent >= self.count and not self.pending


@dataclass
class LoopResult:
    """Wall time of a loop and the generator's own CPU during it."""

    wall_s: float
    generator_cpu_s: float
    extra: dict[str, float] = field(default_factory=dict)


def run_loop(
    publishers: Sequence[Publisher],
    subscribers: Sequence[Subscriber],
    *,
    done: Callable[[], bool],
    limit_s: float,
    others: Sequence[Peer] = (),
) -> LoopResult:
    """Drive every peer until ``done()`` (checked after each round) or fail after ``limit_s``.

    Raises:
        GeneratorError: a peer saw something wrong, or ``limit_s`` passed.
    """
    sel = selectors.DefaultSelector()
    start = time.perf_counter()
    cpu0 = time.process_time()
    for sub in subscribers:
        sub.start(start)
        if not sub.stalled:
            sel.register(sub.sock, selectors.EVENT_READ, sub)
    for peer in [*publishers, *others]:
        sel.register(peer.sock, selectors.EVENT_READ, peer)
    writing: set[Publisher] = set()
    try:
        while True:
            now = time.perf_counter()
            for pub in publishers:
                pub.push(now)
                _track_write(sel, pub, writing)
            if done():
                break
            if now - start > limit_s:
                raise GeneratorError(f"no completion within {limit_s:.0f} s")
            dues = [d for d in (p.next_due(now) for p in publishers) if d is not None]
            timeout = min([0.05, *dues])
            for key, mask in sel.select(timeout):
                peer = key.data
                if mask & selectors.EVENT_READ:
                    peer.readable(time.perf_counter())
                if mask & selectors.EVENT_WRITE:
                    peer.writable()
    finally:
        sel.close()
    return LoopResult(time.perf_counter() - start, time.process_time() - cpu0)


def _track_write(sel: selectors.BaseSelector, pub: Publisher, writing: set[Publisher]) -> None:
    wants = pub.wants_write
    if wants == (pub in writing):
        return
    events = selectors.EVENT_READ | (selectors.EVENT_WRITE if wants else 0)
    sel.modify(pub.sock, events, pub)
    if wants:
        writing.add(pub)
    else:
        writing.discard(pub)


def percentile_ms(values: Sequence[float], q: float) -> float:
    """The ``q`` quantile of latencies in seconds, in milliseconds (nearest rank)."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))] * 1e3


def close_all(peers: Sequence[Peer]) -> None:
    """Close every peer's socket (errors ignored)."""
    for peer in peers:
        with contextlib.suppress(OSError):
            peer.sock.close()


def set_recv_buffer(sock: socket.socket, size: int) -> None:
    """Shrink a socket's receive buffer (a stalled subscriber holds little)."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
