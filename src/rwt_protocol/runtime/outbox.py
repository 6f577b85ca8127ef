"""The bounded queue of frames waiting to go out on one connection.

D24: the bytes queued for a peer are bounded; above the bound
the oldest *topic* messages are dropped, never service responses, action results
or status messages. Drops are counted so the session can report them. The parts
of one fragmented message share a ``group`` and are dropped together, so that a
peer is not left with a message it can never complete (D19); a message whose
first parts were already taken is never cut either. The writer takes frames in
bounded batches (``take``), so the frames a transport holds outside the queue
stay small too. Dropping is amortised O(1) per frame.

The bound is on memory, not only payload: each queued frame is charged its
payload plus ``FRAME_OVERHEAD_BYTES`` (benchmarks B8), so a peer that reads
nothing holds at most about ``limit_bytes`` of server memory whatever the frame
size (at 100 B a frame, counting payload alone let the queue take twice the
limit).

One topic message larger than the whole limit (a 20 MB point cloud under the
16 MiB default) would be dropped by that rule however fast the peer reads. It
is *held* instead when no other topic message is queued: it waits alone, and
while it does the queue counts as full, so every other topic message is dropped
(D24) rather than queued behind it. What the queue holds so stays within the
limit plus one message. Where other topic messages wait, such a message cannot
go: it is dropped and counted apart (``dropped_oversized``), so that the
session can tell the peer which option it needs (docs/limits.md).

A queue may also bound the topic messages it holds by count (``max_messages``:
a Foxglove client's backlog, as the Foxglove SDK bounds it): past it the
oldest topic messages go, as past the byte limit. It counts droppable frames,
so a fragmented message counts each of its parts.

A topic message may also come with a lifespan (``extend``'s ``lifespan``: a
sample from ROS 2, whose publisher no input backpressure can slow; docs/ros2.md,
"Latency under rate"): the queue holds at most that span of its ``key``'s (its
topic's) messages. When a message comes, the messages of its topic that came
more than their lifespan before it are dropped, wherever they wait (their
frames are left in place, dead, and skipped when they reach the head: dropping
stays amortised O(1)), and counted in ``dropped`` and ``expired``. So a reader
that falls behind a steady stream waits behind at most the lifespan's worth of
it and gets the newest messages rather than old ones, while a burst that came
within the lifespan reaches it whole however slowly it reads, and the newest
message of a topic always stays. Messages without a lifespan (a rosbridge
client's, which input backpressure paces, replies) never expire: the byte
bound alone applies.

A topic message may also come with an end (protocol 2.1.0's lifespan, D63:
``extend``'s and ``push_timed``'s ``expires``, the monotonic time its lifespan
ends): it is never taken after it, whatever the session that queued it (``take``
is given the time; such a message reaching the head too late is dropped and
counted in ``dropped`` and ``expired``, and one that comes already past it is
never queued). It may come with a subscription's QoS too (D63-D64; ``extend``'s
``rule``, a ``QueueRule``): at most ``rule.depth`` of its key's messages wait
(the oldest go, counted in ``dropped``), and a best-effort one
(``rule.best_effort``) is dropped first whenever the queue is over its high
watermark, oldest first, the newest staying: it never holds a publisher back
(input backpressure) and never pushes out a reliable subscription's messages.
What such a message was queued with is checked per message only for those.

A queue may also be charged to the server's memory budget (``account``, a
``memory.MemoryAccount``; D44): what it holds is charged as it changes, with
what the transport took and is still writing (until ``sent``; the hot paths,
``push_droppable`` and ``push_timed``, once for a run at ``settle``), and while
the budget is full a queue whose connection it judges over its part drops its
own oldest topic messages when messages come (``MemoryAccount.excess``), the
newest staying, as past its own limit.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    from .memory import MemoryAccount

__all__ = [
    "FRAME_OVERHEAD_BYTES",
    "OutFrame",
    "Outbox",
    "QueueRule",
    "SessionStats",
    "water_marks",
]

FRAME_OVERHEAD_BYTES = 192
"""Memory a queued frame costs beyond its payload, in bytes, charged against the limit.

Measured on CPython 3.11, x86_64, glibc (a stalled subscriber's queue of
JSON publish frames, RSS growth less payload, divided by the frames): 117 B a
frame at 4 KB, 174 B at 150 B. It is the ``OutFrame`` (72 B with its GC
header), the payload's ``bytes`` header (33 B) and allocator rounding, the
WebSocket header kept on the frame (a 35-43 B ``bytes``) and the queue's slot;
192 B leaves a margin.
"""


def water_marks(limit_bytes: int) -> tuple[int, int]:
    """The (high, low) watermarks in bytes of a queue bounded at ``limit_bytes``.

    The one input-backpressure rule of every queue a reader may be held for
    (a connection's outbox, a link's queue for the other middleware): a reader
    whose input pushed a queue past half its bound waits until it is under a
    quarter (docs/limits.md, input backpressure).
    """
    return limit_bytes // 2, limit_bytes // 4


@dataclass(frozen=True, slots=True)
class QueueRule:
    """What a subscription's QoS asks of its messages in a queue (D63, D64; module text).

    Attributes:
        depth: at most this many of the key's messages wait (0: no count bound).
        best_effort: dropped first while the queue is over its high watermark.
    """

    depth: int = 0
    best_effort: bool = False


class _Timed:
    """A queued message with a lifespan or a rule: shared by the timing entries of its frames."""

    __slots__ = (
        "best_effort",
        "came",
        "cost",
        "dead",
        "expires",
        "frames",
        "key",
        "lifespan",
        "queued",
    )

    def __init__(self, came: float, lifespan: float, key: str, frames: int) -> None:
        self.came = came  # monotonic seconds
        self.lifespan = lifespan  # seconds
        self.key = key  # the message's topic
        self.frames = frames
        self.cost = 0  # bytes charged for its frames
        self.dead = False  # dropped for its lifespan; its frames still in the queue
        self.queued = True  # among its key's (``_by_key``): none of its frames left yet
        self.expires = math.inf  # monotonic seconds after which it is never taken
        self.best_effort = False


@dataclass(slots=True)
class OutFrame:
    """One frame to send; shared by the subscribers of a form, so never changed once queued.

    Not a frozen dataclass only for speed: a frozen one's ``__init__`` sets each
    field through ``object.__setattr__``, 1.4 us a frame against 0.7 us, paid per
    message and subscription id of a burst (benchmarks/README.md, Foxglove). Only
    the transport writes ``header``, once.

    Attributes:
        data: the payload (UTF-8 JSON text or CBOR bytes).
        binary: send as a binary frame (CBOR, D27) rather than text.
        droppable: may be dropped under pressure (topic messages only).
        group: the parts of one fragmented message share a group (any hashable
            that no other message uses); None for a whole message.
        header: the transport's header for this frame (a WebSocket frame
            header), made by the first connection that sends it and reused by
            every other: one frame object goes to all subscribers of a form
            (``encoding.publish_frames``), so it is framed once (benchmarks/README.md). Only
            the header is kept, so a queued frame costs its payload once. With a
            ``prefix``, it frames the prefix and ``data`` together.
        prefix: bytes sent before ``data`` in the same message: a header of one
            connection's own (a Foxglove message data header) in front of a
            payload that many connections share, which so is not copied for
            each. Empty for every rosbridge frame; only the WebSocket transport
            is given frames with one, and sends ``prefix + data`` as one message.
    """

    data: bytes
    binary: bool = False
    droppable: bool = False
    group: object = None
    header: bytes | None = field(default=None, compare=False, repr=False)
    prefix: bytes = b""


class Outbox:
    """FIFO of ``OutFrame`` with a byte bound that drops the oldest droppable frames.

    Args:
        limit_bytes: the most bytes kept queued, each frame counting its
            payload plus ``frame_overhead_bytes``; frames that may not be
            dropped are always queued, even beyond it.
        frame_overhead_bytes: the memory charged per frame beyond its payload.
        max_messages: the most droppable frames kept queued (None: no count
            bound); past it the oldest go, the newest always stays.

    Attributes:
        dropped: topic messages dropped so far (a fragmented one counts once),
            expired ones included.
        expired: of those, messages dropped for their lifespan (module text).
        stale: of those, messages past their end when they came, never queued: a
            lifespan kept, not a slow peer (``backpressure`` tells nobody of them).
        dropped_oversized: of those, messages larger than ``limit_bytes`` that
            came while other topic messages were queued.
        dropped_memory: of those, messages dropped for the server's memory budget
            (``account``, D44).
        topic_messages: topic messages queued so far (a fragmented one counts once),
            dropped ones included: the ones sent are ``topic_messages - dropped``
            once the queue is empty.
        taken_frames: frames the transport took so far (replies included).
        high_water_bytes: fill above which the input that fills this queue is
            paused, half the limit (``water_marks``). Input backpressure
            (docs/limits.md): a reader whose frames pushed a queue over this
            mark stops reading until it is back under ``low_water_bytes``, within
            the peer's hold budget (``--hold-budget``), so a peer that keeps up
            on average loses nothing to a burst and the drop rule (D24) is left
            to peers that read slower than their topics come, or not at all.
        low_water_bytes: fill under which paused input resumes, a quarter of the limit.
        account: the connection's account of the server's memory budget (D44), or
            None; set once, before anything is queued.
    """

    # slots: a hot-path object of every connection, with more attributes than CPython
    # 3.11 shares keys for (30): without them each read of one went through a dict
    __slots__ = (
        "_best_effort",
        "_by_key",
        "_bytes",
        "_charged",
        "_dead_frames",
        "_expiring",
        "_frames",
        "_held_bytes",
        "_held_frames",
        "_held_timed",
        "_in_flight",
        "_kept_bytes",
        "_peak",
        "_per_message",
        "_sending_group",
        "_times",
        "_topic_frames",
        "account",
        "dropped",
        "dropped_memory",
        "dropped_oversized",
        "expired",
        "frame_overhead_bytes",
        "high_water_bytes",
        "limit_bytes",
        "low_water_bytes",
        "max_messages",
        "stale",
        "taken_frames",
        "topic_messages",
    )

    def __init__(
        self,
        limit_bytes: int,
        frame_overhead_bytes: int = FRAME_OVERHEAD_BYTES,
        max_messages: int | None = None,
    ) -> None:
        self._frames: deque[OutFrame] = deque()
        self._bytes = 0
        self._kept_bytes = 0
        self._topic_frames = 0  # queued frames that may be dropped (``max_messages``)
        self.max_messages = None if max_messages is None else max(1, max_messages)
        self._per_message = (
            0 if self.max_messages is None else max(1, limit_bytes // self.max_messages)
        )
        self._sending_group: object = None  # partly taken: the rest must go too
        # The oversized message held alone: its frames still queued and their charge.
        # It is always the oldest droppable message, so ``take`` meets its frames first.
        self._held_frames = 0
        self._held_bytes = 0
        self.limit_bytes = limit_bytes
        self.high_water_bytes, self.low_water_bytes = water_marks(limit_bytes)
        self.frame_overhead_bytes = frame_overhead_bytes
        self.dropped = 0
        self.dropped_oversized = 0
        self.dropped_memory = 0
        self.topic_messages = 0
        self.taken_frames = 0
        self.expired = 0
        self.stale = 0
        self._peak = 0  # ``peak_bytes`` before the bytes queued now
        # Once a message with a lifespan came: one entry per queued frame, in step with
        # ``_frames`` (None for a frame without one); by key, its messages none of whose
        # frames has left, oldest first; and how many dead frames wait for the head.
        self._times: deque[_Timed | None] | None = None
        self._by_key: dict[str, deque[_Timed]] = {}
        self._dead_frames = 0
        self._expiring = 0  # queued messages with an ``expires`` (their key's list holds them)
        self._held_timed: _Timed | None = None  # the held message's record, if it has one
        self._best_effort: deque[_Timed] = deque()  # best-effort messages, oldest first
        self.account: MemoryAccount | None = None
        self._charged = 0  # bytes charged to ``account``
        self._in_flight = 0  # bytes taken by the transport and not yet ``sent``

    def __len__(self) -> int:
        return len(self._frames) - self._dead_frames

    @property
    def queued_bytes(self) -> int:
        """Bytes charged for the queued frames: payload plus the per-frame overhead."""
        return self._bytes

    @property
    def peak_bytes(self) -> int:
        """The most bytes held at once (after drops), charged as ``queued_bytes`` is."""
        # kept when frames leave (``take``, drops), not per push: between two of those
        # the queue only grows, so its peak is where it stood before one of them, or now
        return max(self._peak, self._bytes)

    @property
    def undroppable_bytes(self) -> int:
        """Bytes charged for the queued frames that may not be dropped."""
        return self._kept_bytes

    @property
    def topic_frames(self) -> int:
        """Droppable frames queued (what ``max_messages`` bounds)."""
        return self._topic_frames

    @property
    def fill_bytes(self) -> int:
        """How full the queue is, in bytes, for the watermarks (input backpressure).

        With ``max_messages`` a topic message counts at least its share of the
        byte limit (``limit_bytes / max_messages``), so that either bound
        congests; else the bytes queued.
        """
        if not self._per_message:
            return self._bytes
        return max(self._bytes, self._topic_frames * self._per_message)

    @property
    def held_bytes(self) -> int:
        """Bytes charged for the frames of a held message over ``limit_bytes`` still queued."""
        return self._held_bytes

    @property
    def over_limit(self) -> bool:
        """Whether more than ``limit_bytes`` are queued besides a held message.

        Only undroppable frames remain over it: a held message is the one topic
        message allowed past the limit, and is not a sign of a slow peer.
        """
        return self._bytes - self._held_bytes > self.limit_bytes

    def fits_kept(self, frames: Iterable[OutFrame]) -> bool:
        """Whether ``frames``, never to be dropped, fit under ``limit_bytes`` with those kept.

        An empty queue takes anything, so one request larger than the limit
        can still go through alone. Used to refuse a provider's requests that do
        not fit rather than close it (docs/limits.md, provider busy).
        """
        if not self._kept_bytes:
            return True
        cost = sum(len(frame.data) + self.frame_overhead_bytes for frame in frames)
        return self._kept_bytes + cost <= self.limit_bytes

    def push(self, frame: OutFrame) -> None:
        """Queue ``frame``, dropping the oldest droppable frames if over the bound."""
        self.extend((frame,))

    def extend(
        self,
        frames: Sequence[OutFrame],
        now: float | None = None,
        lifespan: float = 0.0,
        key: str = "",
        rule: QueueRule | None = None,
        expires: float = math.inf,
    ) -> None:
        """Queue the frames of one message (all its parts), then drop if over the bound.

        Queueing every part before dropping lets a message's parts go together.
        A topic message larger than ``limit_bytes`` is held when no other topic
        message is queued, and dropped (``dropped_oversized``) otherwise; while
        one is held, every other topic message is dropped on arrival. The
        frames of one message are all droppable or none.

        Args:
            frames: the message's frames.
            now: when the message came (monotonic seconds), for ``lifespan``.
            lifespan: with ``now``, seconds of ``key``'s topic messages this queue
                holds at most (module text); 0: no such bound.
            key: the message's topic, for ``lifespan`` and ``rule``.
            rule: with ``now``, the subscription's QoS for a topic message (D63, D64).
            expires: with ``now``, the monotonic time after which the topic message
                is never taken (its lifespan's end, D63; module text).
        """
        droppable = bool(frames) and frames[0].droppable
        if droppable:
            self.topic_messages += 1
        if self._held_frames and droppable:
            self.dropped += 1  # the queue is full with the held message
            return
        if droppable and now is not None and expires <= now:
            self.dropped += 1  # past its lifespan already (D63): never queued
            self.expired += 1
            self.stale += 1
            return
        ends = droppable and expires != math.inf
        timed = self._note_timing(frames, now, lifespan, key, rule is not None or ends)
        message = self._append(frames)
        if timed is not None:
            self._timed_queued(timed, message, rule, expires)
        if self._bytes > self.limit_bytes:
            if message > self.limit_bytes and frames[0].droppable:
                self._hold(len(frames), message)
                if self._held_frames:
                    self._held_timed = timed
            elif not self._held_frames:  # a held message is the only droppable one
                self._shed()
        elif self.max_messages is not None and self._topic_frames > self.max_messages:
            self._shed()
        if self.account is not None:
            self._settle()

    def _timed_queued(
        self, timed: _Timed, cost: int, rule: QueueRule | None, expires: float
    ) -> None:
        """Note the cost of a message with a lifespan, an end or a rule just queued; apply them."""
        timed.cost = cost
        if expires != math.inf:
            timed.expires = expires
            self._expiring += 1
        oldest = self._by_key[timed.key][0]
        if timed.came - oldest.came > oldest.lifespan:
            self._expire(timed.key, timed.came)
        if rule is not None:
            self._apply_rule(timed, rule)

    def _append(self, frames: Sequence[OutFrame]) -> int:
        """Queue ``frames`` as they are (``extend``'s first step); return their cost, bytes."""
        overhead = self.frame_overhead_bytes
        message = 0
        for frame in frames:
            self._frames.append(frame)
            cost = len(frame.data) + overhead
            self._bytes += cost
            message += cost
            if not frame.droppable:
                self._kept_bytes += cost
            else:
                self._topic_frames += 1
        return message

    def push_droppable(self, frame: OutFrame) -> None:
        """``push`` one whole topic message (``droppable``, no ``group``): the hot path.

        The same rules as ``extend`` of one frame (without a lifespan), in the
        fewest steps while the queue is within its bounds (a burst's per-message cost).
        The memory budget is charged at the caller's ``settle``, once for a run.
        """
        self.topic_messages += 1
        if self._held_frames:
            self.dropped += 1  # the queue is full with the held message
            return
        if self._times is not None:
            self._times.append(None)
        self._frames.append(frame)
        self._topic_frames += 1
        cost = len(frame.data) + self.frame_overhead_bytes
        self._bytes += cost
        self._bound_one(cost)

    def push_timed(
        self, frame: OutFrame, now: float, lifespan: float, key: str, expires: float = math.inf
    ) -> None:
        """``extend((frame,), now, lifespan, key, None, expires)`` of one message: the hot path.

        ``frame`` is droppable with no ``group``; ``lifespan`` is over 0 (seconds),
        or ``expires`` is finite (the message's end, module text). The same rules
        as ``extend`` in fewer steps while the queue is within its bounds: a ROS 2
        burst's per-message and per-subscriber cost (``Session.deliver_many``), a
        Foxglove client's run of messages with a lifespan. The memory budget is
        charged at the caller's ``settle``, once for a run.
        """
        self.topic_messages += 1
        if self._held_frames:
            self.dropped += 1  # the queue is full with the held message
            return
        if expires <= now:
            self.dropped += 1  # past its lifespan already (D63): never queued
            self.expired += 1
            self.stale += 1
            return
        times = self._times
        if times is None:
            times = self._times = deque([None] * len(self._frames))
        cost = len(frame.data) + self.frame_overhead_bytes
        timed = _Timed(now, lifespan if lifespan > 0 else math.inf, key, 1)
        timed.cost = cost
        if expires != math.inf:
            timed.expires = expires
            self._expiring += 1
        times.append(timed)
        waiting = self._by_key.get(key)
        if waiting is None:
            waiting = self._by_key[key] = deque()
        waiting.append(timed)
        self._frames.append(frame)
        self._topic_frames += 1
        self._bytes += cost
        oldest = waiting[0]
        if now - oldest.came > oldest.lifespan:
            self._expire(key, now)
        self._bound_one(cost)

    def _bound_one(self, cost: int) -> None:
        """Apply the bounds after one whole topic message of ``cost`` bytes was queued."""
        if self._bytes > self.limit_bytes:
            if cost > self.limit_bytes:
                self._hold(1, cost)
            else:
                self._shed()
        elif self.max_messages is not None and self._topic_frames > self.max_messages:
            self._shed()

    def _hold(self, count: int, cost: int) -> None:
        """Hold the message just queued (``count`` frames, ``cost`` bytes) over the limit.

        It may wait only alone: where other topic messages wait, it is dropped.
        """
        if self._bytes - cost > self._kept_bytes:  # other topic messages wait: it cannot go
            for _ in range(count):
                self._frames.pop()
                self._forget(last=True)
            self._topic_frames -= count
            self._bytes -= cost
            self.dropped += 1
            self.dropped_oversized += 1
            return
        self._held_frames = count
        self._held_bytes = cost

    def take(self, max_bytes: int | None = None, now: float | None = None) -> list[OutFrame]:
        """Remove and return the oldest frames, oldest first.

        Args:
            max_bytes: stop once this many payload bytes are taken (at least one
                frame is taken when any is queued); None takes everything.
            now: monotonic seconds: a message whose lifespan ended before it is
                dropped instead of taken (``extend``'s ``expires``, D63); None
                checks none.
        """
        overhead = self.frame_overhead_bytes
        self._peak = max(self._peak, self._bytes)
        queued = self._frames
        count = len(queued) - self._dead_frames
        expiring = self._expiring and now is not None
        if (
            count
            and not expiring
            and (max_bytes is None or self._bytes - count * overhead <= max_bytes)
        ):
            return self._take_all(count)
        frames: list[OutFrame] = []
        taken = 0  # payload: what the transport will write
        if expiring:
            assert now is not None  # (``expiring``)
            self._skip_expired(now)
        else:
            self._skip_dead()
        while self._frames and (
            max_bytes is None or not frames or taken + len(self._frames[0].data) <= max_bytes
        ):
            frame = self._frames.popleft()
            self._forget()
            frames.append(frame)
            taken += len(frame.data)
            if not frame.droppable:
                self._kept_bytes -= len(frame.data) + overhead
            else:
                self._topic_frames -= 1
                if self._held_frames:  # the first droppable frames are the held message's
                    self._held_frames -= 1
                    self._held_bytes -= len(frame.data) + overhead
            if expiring:
                assert now is not None  # (``expiring``)
                self._skip_expired(now)
            else:
                self._skip_dead()
        self._bytes -= taken + len(frames) * overhead
        self._in_flight += taken + len(frames) * overhead
        self.taken_frames += len(frames)
        last = frames[-1].group if frames else None
        following = self._frames[0].group if self._frames else None
        self._sending_group = last if last is not None and last == following else None
        if self.account is not None:
            self._settle()
        return frames

    def _take_all(self, count: int) -> list[OutFrame]:
        """``take`` of everything (a burst a writer takes whole): no per-frame bookkeeping."""
        queued = self._frames
        whole = self._live() if self._dead_frames else list(queued)
        self._in_flight += self._bytes
        queued.clear()
        self._bytes = self._kept_bytes = self._topic_frames = 0
        self._held_frames = self._held_bytes = 0
        self._held_timed = None
        self.taken_frames += count
        self._sending_group = None
        if self._times is not None:
            self._times.clear()
            self._by_key.clear()
            self._best_effort.clear()
            self._dead_frames = 0
        if self.account is not None:
            self._settle()
        return whole

    def sent(self) -> None:
        """The transport wrote what it took: it is no longer held (nor charged)."""
        if self._in_flight:
            self._in_flight = 0
            if self.account is not None:
                self._settle()

    def drain(self) -> list[OutFrame]:
        """Remove and return every queued frame, oldest first."""
        return self.take()

    def _over(self) -> bool:
        """Whether the queue holds more than its bounds (bytes, or topic frames by count)."""
        if self._bytes > self.limit_bytes:
            return True
        limit = self.max_messages
        return limit is not None and self._topic_frames > limit

    def shed_to(self, cap: int) -> None:
        """Drop the oldest topic messages until at most ``cap`` bytes are queued.

        Replies and statuses stay, the newest frame stays, and so does a held
        message over the limit (it is the only topic message queued). Dropped
        messages are counted in ``dropped``. For a session making room for
        what waits to be queued (``pngout``) or for the memory budget (D44).
        """
        if self._bytes > cap and self._topic_frames and not self._held_frames:
            self._shed(cap)
            if self.account is not None:
                self._settle()

    def settle(self) -> None:
        """Charge the memory budget with what changed since (``push_droppable``, ``push_timed``).

        Every other change settles at once; what was pushed and not settled is
        charged at the next change (a ``take``) otherwise.
        """
        if self.account is not None:
            self._settle()

    def _settle(self) -> None:
        """Charge ``account`` with what changed; drop down to the share while the budget is full."""
        account = self.account
        assert account is not None
        held = self._bytes + self._in_flight
        delta = held - self._charged
        if not delta:
            return
        self._charged = held
        budget = account.budget
        if account.held > 0 < delta and budget.used + delta <= budget.limit and not budget.wanted:
            # the hot path (a message more, room in the budget): ``charge`` in the fewest steps
            if not account.closed:
                account.held += delta
                budget.used += delta
            return
        account.charge(delta)
        if delta < 0 or self._held_frames or not self._topic_frames:
            return
        excess = account.excess(self.limit_bytes)
        if excess:
            dropped = self.dropped
            self._shed(max(0, self._bytes - excess))
            self.dropped_memory += self.dropped - dropped
            freed = self._bytes + self._in_flight - self._charged
            self._charged += freed
            account.charge(freed)

    def _shed(self, cap: int | None = None) -> None:
        """Drop the oldest droppable frames while over the bounds (or over ``cap`` bytes)."""
        kept: list[OutFrame] = []
        kept_times: list[_Timed | None] = []
        times = self._times
        if self._frames:
            self._peak = max(
                self._peak, self._bytes - len(self._frames[-1].data) - self.frame_overhead_bytes
            )
        groups: set[object] = set()
        newest = self._frames[-1] if self._frames else None  # always stays (count bound)
        while self._frames and (self._over() if cap is None else self._bytes > cap):
            if self._frames[0] is newest and (cap is not None or self._bytes <= self.limit_bytes):
                break
            frame = self._frames.popleft()
            timing = self._forget()
            if timing is not None and timing.dead:
                continue  # already dropped and uncharged
            if frame.droppable and (frame.group is None or frame.group != self._sending_group):
                self._drop(frame, groups)
            else:
                kept.append(frame)
                kept_times.append(timing)
        # The rest of a message whose first parts were dropped follows right after them.
        while (
            self._frames and self._frames[0].group is not None and self._frames[0].group in groups
        ):
            self._forget()
            self._drop(self._frames.popleft(), groups)
        self._frames.extendleft(reversed(kept))  # the kept ones keep their place
        if times is not None:
            times.extendleft(reversed(kept_times))

    def _apply_rule(self, timed: _Timed, rule: QueueRule) -> None:
        """Apply a subscription's QoS to the message just queued (D63, D64; module text)."""
        if rule.depth:
            waiting = self._by_key[timed.key]
            while len(waiting) > rule.depth:  # the history keeps the newest ``depth``
                self._kill(waiting[0], expired=False)
        if rule.best_effort:
            timed.best_effort = True
            self._best_effort.append(timed)
        if self._best_effort and self.fill_bytes > self.high_water_bytes:
            self._shed_best_effort()

    def _shed_best_effort(self) -> None:
        """Drop best-effort messages, oldest first, while over the high watermark (D64).

        The newest best-effort message stays, so a subscription that reads at all
        gets the latest.
        """
        waiting = self._best_effort
        while waiting and (waiting[0].dead or not waiting[0].queued):
            waiting.popleft()
        while len(waiting) > 1 and self.fill_bytes > self.high_water_bytes:
            timed = waiting.popleft()
            if timed.queued and not timed.dead:
                self._kill(timed, expired=False)

    def _kill(self, timed: _Timed, *, expired: bool) -> None:
        """Drop a queued message whose frames stay in place, dead (``_expire``'s way)."""
        waiting = self._by_key[timed.key]
        if waiting[0] is timed:
            waiting.popleft()
        else:
            waiting.remove(timed)
        if not waiting:
            del self._by_key[timed.key]
        timed.dead = True
        timed.queued = False
        if not math.isinf(timed.expires):
            self._expiring -= 1
        if timed is self._held_timed:  # the held message goes: the queue takes others again
            self._held_timed = None
            self._held_frames = self._held_bytes = 0
        self._bytes -= timed.cost
        self._topic_frames -= timed.frames
        self._dead_frames += timed.frames
        self.dropped += 1
        if expired:
            self.expired += 1

    def _expire(self, key: str, newest: float) -> None:
        """Drop ``key``'s messages that came more than their lifespan before ``newest``.

        They are the oldest of their key; each is looked at once (module text).
        """
        waiting = self._by_key[key]
        while newest - waiting[0].came > waiting[0].lifespan:  # the newest never expires
            timed = waiting.popleft()
            timed.dead = True
            timed.queued = False
            if not math.isinf(timed.expires):
                self._expiring -= 1
            self._bytes -= timed.cost
            self._topic_frames -= timed.frames
            self._dead_frames += timed.frames
            self.dropped += 1
            self.expired += 1

    def _note_timing(
        self,
        frames: Sequence[OutFrame],
        now: float | None,
        lifespan: float,
        key: str,
        ruled: bool = False,
    ) -> _Timed | None:
        """Record the lifespan (or rule, ``ruled``) of the message ``frames`` is about to queue.

        Returns:
            Its record, or None if it has neither.
        """
        times = self._times
        if now is None or (lifespan <= 0 and not ruled) or not frames or not frames[0].droppable:
            if times is not None:
                times.extend([None] * len(frames))
            return None
        if times is None:
            times = self._times = deque([None] * len(self._frames))
        timed = _Timed(now, lifespan if lifespan > 0 else math.inf, key, len(frames))
        if len(frames) == 1:
            times.append(timed)
        else:
            times.extend([timed] * len(frames))
        waiting = self._by_key.get(key)
        if waiting is None:
            waiting = self._by_key[key] = deque()
        waiting.append(timed)
        return timed

    def _forget(self, *, last: bool = False) -> _Timed | None:
        """The timing of the frame leaving the head (or the tail: ``last``), now gone.

        A live message leaves its key's list as its first frame leaves the
        queue; a dead frame leaving is one fewer waiting for the head.
        """
        times = self._times
        if times is None:
            return None
        timed = times.pop() if last else times.popleft()
        if timed is None:
            return None
        if timed.dead:
            self._dead_frames -= 1
        elif timed.queued:
            timed.queued = False
            if not math.isinf(timed.expires):
                self._expiring -= 1
            waiting = self._by_key[timed.key]
            if last:
                waiting.pop()
            else:
                waiting.popleft()  # the oldest of its key: the queue is in order
            if not waiting:
                del self._by_key[timed.key]
        return timed

    def _skip_expired(self, now: float) -> None:
        """``_skip_dead``, and drop a message at the head whose lifespan ended before ``now``.

        Only a message none of whose frames left yet (``queued``): a message is
        never cut once its first part went.
        """
        times = self._times
        while times and self._frames:
            timed = times[0]
            if timed is None:
                return
            if not timed.dead:
                if not timed.queued or timed.expires >= now:
                    return
                self._kill(timed, expired=True)
            self._frames.popleft()
            self._forget()

    def _skip_dead(self) -> None:
        """Pop the dead frames at the head (their bytes were uncharged when they died)."""
        times = self._times
        while self._dead_frames and times and times[0] is not None and times[0].dead:
            self._frames.popleft()
            self._forget()

    def _live(self) -> list[OutFrame]:
        """The queued frames but the dead ones, oldest first."""
        times = self._times
        assert times is not None  # (dead frames come only with timings)
        return [
            frame
            for frame, timed in zip(self._frames, times, strict=True)
            if timed is None or not timed.dead
        ]

    def _drop(self, frame: OutFrame, groups: set[object]) -> None:
        self._bytes -= len(frame.data) + self.frame_overhead_bytes
        self._topic_frames -= 1
        if frame.group is None:
            self.dropped += 1
        elif frame.group not in groups:
            groups.add(frame.group)
            self.dropped += 1


class SessionStats:
    """A session's counts and gauges, read live from its outbox (``ServerSession.stats``).

    One value the transport keeps for the connection's life: each read is the
    count or the gauge at that moment.

    Attributes:
        pending_bytes: bytes of topic messages being made for the outbox off the
            loop (png, ``rwt_protocol.server.pngout``), counted in ``fill_bytes``;
            the protocol that makes them keeps it.
    """

    __slots__ = ("_outbox", "pending_bytes")

    def __init__(self, outbox: Outbox) -> None:
        self._outbox = outbox
        self.pending_bytes = 0

    @property
    def queued_bytes(self) -> int:
        """Bytes charged for the frames waiting to be taken."""
        return self._outbox.queued_bytes

    @property
    def queued_reply_bytes(self) -> int:
        """Bytes of queued frames that are never dropped (replies, statuses; D24)."""
        return self._outbox.undroppable_bytes

    @property
    def fill_bytes(self) -> int:
        """How full the outbox is for the watermarks, ``pending_bytes`` included."""
        return self._outbox.fill_bytes + self.pending_bytes

    @property
    def topic_messages(self) -> int:
        """Topic messages queued so far, those dropped since included."""
        return self._outbox.topic_messages

    @property
    def dropped_frames(self) -> int:
        """Topic messages dropped so far because the peer read too slowly (D24)."""
        return self._outbox.dropped

    @property
    def expired_messages(self) -> int:
        """Of ``dropped_frames``, messages a newer one outdated (``Outbox.expired``)."""
        return self._outbox.expired

    @property
    def taken_frames(self) -> int:
        """Frames the transport took so far (topic messages and replies)."""
        return self._outbox.taken_frames
