"""The outgoing side of every protocol's session: the bounded outbox under its rules.

``Sender`` is the part of ``connection.SessionBase`` that queues for the peer and
hands frames to the transport: the bounded outbox (``outbox.Outbox``: bytes, and
topic messages by count where the protocol bounds them), the slow-consumer watch
over it (``backpressure.SlowConsumerWatch``: the first drop of an episode told, a
peer that stays over its limit without reading closed, D24), and the connection's
account of the server's memory budget (``memory.MemoryAccount``, D44: what its
outbox and the messages being made for it hold, and the slow-consumer rule while
the budget is full). A protocol queues through ``send_frames`` (a message of one or
several frames, replies included) and ``queue_run`` (a run of topic messages: the
one hot-path entry), never into the outbox directly. A transport with a second, lossy
way out (WebRTC's lossy data channel, D36) opens a lossy lane here (``lossy.LossyLane``):
the messages of the subscriptions made on it wait there, latest-only per topic.

It is a part of the session, not an object of its own: the hot path reads the
session's own attributes (its time, whether it sends), with no call between.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, ClassVar

from .commands import CloseCode
from .lossy import LossyLane
from .memory import PRESSURE_FLOOR_BYTES

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from ..ports import MessageEvent
    from .backpressure import SlowConsumerWatch
    from .lifecycle import State
    from .memory import MemoryAccount
    from .outbox import Outbox, OutFrame, QueueRule, SessionStats
    from .rules import ClientRules
    from .timers import Timer

__all__ = ["Sender"]

_NO_END = math.inf  # (a module constant: no attribute lookup per run)


class Sender:
    """The outgoing side of a session (the module's text); ``SessionBase`` is made of it.

    Attributes:
        stats: the session's counts and gauges, read live (``ServerSession.stats``).
        wake_above_bytes: fill past which each output wakes the transport
            (``ServerSession``): the high watermark, or lower while the transport
            watches for the peer to fall behind.
    """

    wakes_each_run: ClassVar[bool] = False
    """Whether ``queue_run`` wakes the transport after every run, not only when the
    outbox was empty or is past ``wake_above_bytes`` (``ServerSession``: a protocol may
    wake more often). A Foxglove client's bursts are gathered into fewer writes so
    (``rwt_transports.gather``: output during a gathering marks a burst)."""

    stats: SessionStats
    wake_above_bytes: int
    _outbox: Outbox
    _watch: SlowConsumerWatch
    _memory: MemoryAccount | None
    _now: float
    _sends: bool
    _state: State
    _on_output: Callable[[], None] | None
    _lossy: LossyLane | None  # a transport's lossy channel (D36)
    _config: ClientRules

    if TYPE_CHECKING:  # the session's other parts, which the sender calls

        def request_close(self, code: CloseCode, reason: str, *, abort: bool = False) -> None:
            """The lifecycle's (``lifecycle.Lifecycle.request_close``)."""
            raise NotImplementedError

        def call_at(self, deadline: float, callback: Callable[[float], None]) -> Timer:
            """The session's timers (``SessionBase.call_at``)."""
            raise NotImplementedError

        def taken(self, frames: list[OutFrame]) -> None:
            """The protocol's look at the frames taken (``SessionBase.taken``)."""
            raise NotImplementedError

    def message_end(self, event: MessageEvent, lifespan_s: float = math.inf) -> float:
        """The monotonic time after which ``event`` is never sent to this peer (D63).

        One rule for every front end that subscribes: the earlier of the end its
        topic's offer gave it (``MessageEvent.expires``) and its publication plus
        the subscription's lifespan, seconds: ``lifespan_s`` where the
        subscription asked one, else the server's (``ClientRules.qos_lifespan_s``,
        ``--qos-lifespan``). What the protocol queues with this end
        (``send_frames``, ``queue_run``) the outbox never gives the transport after
        it (``outbox``). ``math.inf``: none.
        """
        if lifespan_s == math.inf:
            lifespan_s = self._config.qos_lifespan_s
        if lifespan_s == math.inf:
            return event.expires
        return min(event.expires, event.now + lifespan_s)

    def send_frames(
        self,
        frames: Sequence[OutFrame],
        topic: str | None = None,
        lifespan: float = 0.0,
        rule: QueueRule | None = None,
        expires: float = math.inf,
    ) -> None:
        """Queue the frames of one message (its parts stay together, D24) and wake the transport.

        Past the limit, the oldest topic messages go (D24); when undroppable
        frames alone exceed the limit the peer is not reading at all, and the
        connection is closed rather than let memory grow. A topic message
        larger than the limit goes out alone or is dropped with a status naming
        ``--send-buffer-limit`` (``outbox``, ``backpressure``).

        Args:
            frames: the frames of one message, shared with other connections (never copied).
            topic: the topic of a message, as the peer spells it, for the status of a drop.
            lifespan: seconds of ``topic``'s messages its queue holds at most
                (``MessageEvent.lifespan``, ``outbox``); 0: no such bound.
            rule: the subscription's QoS for a topic message (``outbox.QueueRule``,
                D63, D64): its depth and reliability in the queue.
            expires: the monotonic time after which a topic message is never sent
                (its lifespan's end, ``message_end``; D63), with or without ``rule``.
        """
        if not self._state.sends:
            return
        outbox = self._outbox
        limit = outbox.limit_bytes
        if outbox.undroppable_bytes > limit and not all(f.droppable for f in frames):
            self.request_close(
                CloseCode.POLICY_VIOLATION,
                f"send buffer overflow: over {limit} bytes unread",
                abort=True,
            )
            return
        was_empty = len(outbox) == 0
        dropped, oversized = outbox.dropped, outbox.dropped_oversized
        outbox.extend(frames, self._now, lifespan, topic or "", rule, expires)
        self._watch.after_push(dropped, oversized, self._now, frames, topic)
        if was_empty or outbox.fill_bytes > self.wake_above_bytes:
            self._wake()  # above the high watermark too: the transport applies backpressure
        self.sweep_memory()

    def queue_run(
        self,
        frames: Sequence[OutFrame],
        topic: str | None,
        now: float,
        lifespan: float = 0.0,
        expires: float = math.inf,
    ) -> None:
        """Queue a run of topic messages, one whole droppable frame each, and wake once.

        The one hot-path entry of every protocol (docs/architecture.md, "How to
        add a protocol"): past the limit the oldest topic messages go (D24), the
        slow-consumer rule sees each drop (``backpressure``), the memory budget
        is settled once for the run (D44), and the transport is woken when the
        outbox was empty or is past ``wake_above_bytes``. A message of several
        frames, or a reply, goes through ``send_frames``.

        Args:
            frames: the messages, in order; each a droppable frame shared with
                other connections (never copied).
            topic: their topic, as the peer spells it, for a drop's status; None
                for frames of no topic (a protocol's time frames).
            now: when they were made (monotonic seconds): the session's time moves
                to it, and a ``lifespan`` counts from it.
            lifespan: seconds of ``topic``'s messages the outbox holds at most
                (``MessageEvent.lifespan``, ``outbox``); 0: no such bound.
            expires: the monotonic time after which none of them is sent (their
                lifespan's end, ``message_end``; D63): a run shares one.
        """
        if not self._sends or not frames:
            return
        if now > self._now:  # (``max``, inline: a call less per run and client)
            self._now = now
        else:
            now = self._now
        outbox = self._outbox
        wake = self.wakes_each_run or len(outbox) == 0  # (no ``len`` call for those that wake)
        dropped, oversized = outbox.dropped, outbox.dropped_oversized
        if lifespan > 0 or expires < _NO_END:
            key = topic or ""
            for frame in frames:
                outbox.push_timed(frame, now, lifespan, key, expires)
                if outbox.dropped != dropped:  # the slow-consumer rule, message by message
                    self._watch.after_push(dropped, oversized, now, (frame,), topic)
                    dropped, oversized = outbox.dropped, outbox.dropped_oversized
        else:
            push = outbox.push_droppable
            for frame in frames:
                push(frame)
                if outbox.dropped != dropped:
                    self._watch.after_push(dropped, oversized, now, (frame,), topic)
                    dropped, oversized = outbox.dropped, outbox.dropped_oversized
        outbox.settle()  # the memory budget, once for the run (D44)
        if outbox.dropped != dropped or outbox._held_frames:  # (``held_bytes``, inline)
            self._watch.after_push(dropped, oversized, now, (), topic)
        on_output = self._on_output  # (``_wake`` inline: a call less per run and client)
        if on_output is not None and (wake or outbox.fill_bytes > self.wake_above_bytes):
            on_output()  # above the high watermark too: the transport applies backpressure
        self.sweep_memory()

    def shed(self, cap: int, topic: str | None) -> None:
        """Drop the oldest topic messages down to ``cap`` bytes, under the slow-consumer rule.

        What waits for the peer (``shed_topic_messages``) is cut to ``cap``; the
        drops start an episode as the outbox's own do (D24), the status naming
        ``topic``.
        """
        outbox = self._outbox
        dropped, oversized = outbox.dropped, outbox.dropped_oversized
        self.shed_topic_messages(cap)
        self._watch.after_push(dropped, oversized, self._now, (), topic)

    def sweep_memory(self) -> None:
        """While the server's memory budget is full, let it sweep its connections (D44).

        Cheap when it is not (one comparison): every path that queues or takes
        output calls it. The sweep itself runs at most once per
        ``memory.PRESSURE_SWEEP_S``, on the session's latest time.
        """
        memory = self._memory
        if memory is None:
            return
        budget = memory.budget
        if budget.used > budget.limit or budget.wanted:  # (``pressed``, inline: every push)
            budget.sweep(self._now)
            if budget.sweeper is None and self._state.sends:  # the next, should nothing happen
                budget.sweeper = self
                self.call_at(budget.next_sweep, self._sweep_due)

    def _sweep_due(self, now: float) -> None:
        """This session's timer for the memory budget's next sweep (``sweep_memory``)."""
        memory = self._memory
        if memory is not None and memory.budget.sweeper is self:
            memory.budget.sweeper = None
            self._now = max(self._now, now)
            self.sweep_memory()

    def make_room(self, excess: int, now: float) -> None:
        """Drop the oldest topic messages worth ``excess`` bytes for the memory budget (D44).

        The slow-consumer rule (D24): the drops are counted and the peer told
        once per episode, replies and statuses stay.
        """
        outbox = self._outbox
        dropped, oversized = outbox.dropped, outbox.dropped_oversized
        self.shed_topic_messages(max(0, outbox.queued_bytes + self.stats.pending_bytes - excess))
        if outbox.dropped != dropped:
            outbox.dropped_memory += outbox.dropped - dropped
            self._watch.after_push(dropped, oversized, now, (), None)

    def shed_topic_messages(self, cap: int) -> None:
        """Drop the oldest topic messages until what waits for the peer is at most ``cap`` bytes.

        What waits: the outbox, and what is being made for it (``pending_bytes``);
        a protocol that makes messages off the loop drops those too.
        """
        self._outbox.shed_to(cap)

    def _memory_pressure(self, now: float) -> None:
        """The server's memory budget is full (its sweep, D44): take from this peer if it lags.

        Stalled, or past its part, it loses its oldest topic messages
        (``MemoryAccount.excess``, ``make_room``); holding more than
        ``memory.PRESSURE_FLOOR_BYTES``, it is closed as a slow consumer if it
        takes nothing for ``--send-timeout`` (``SlowConsumerWatch.memory_pressed``).
        """
        account = self._memory
        if account is None or not self._state.sends:
            return
        excess = account.excess(self._outbox.limit_bytes)
        if excess:
            self.make_room(excess, now)
        if account.held > PRESSURE_FLOOR_BYTES:
            self._watch.memory_pressed(now)

    def frames_to_send(
        self, max_bytes: int | None = None, now: float | None = None
    ) -> list[OutFrame]:
        """Take the frames queued for the peer, oldest first.

        Args:
            max_bytes: take at most about this many payload bytes (at least one
                frame); None takes every frame. Taking frames counts as progress
                for the send timeout (D24).
            now: monotonic seconds of the take: a message past its lifespan is
                dropped, not taken (``outbox``, D63); None: the session's latest time.
        """
        if now is None:
            now = self._now
        elif now > self._now:
            self._now = now
        frames = self._outbox.take(max_bytes, now)
        if frames:
            if self._memory is not None:
                self._memory.took(self._now)
            self._watch.after_take()
            self.taken(frames)
            self.sweep_memory()
        return frames

    def frames_sent(self) -> None:
        """The transport wrote the frames it took: they are no longer held (D44)."""
        self._outbox.sent()

    @property
    def outbox(self) -> Outbox:
        """The bounded queue of frames for the peer (``outbox.Outbox``), to read its counts.

        What a protocol queues goes through ``send_frames`` and ``queue_run``,
        never into the outbox directly: they apply the slow-consumer rule.
        """
        return self._outbox

    @property
    def memory(self) -> MemoryAccount | None:
        """This connection's account of the server's memory budget (D44), or None."""
        return self._memory

    @property
    def water_marks(self) -> tuple[int, int]:
        """The outbox's (high, low) watermarks in bytes, for input backpressure (docs/limits.md)."""
        return self._outbox.high_water_bytes, self._outbox.low_water_bytes

    def _wake(self) -> None:
        if self._on_output is not None:
            self._on_output()

    def open_lossy_lane(self, max_message_bytes: int, on_output: Callable[[], None]) -> LossyLane:
        """Open the lane of the transport's lossy channel (D36; ``lossy.LossyLane``).

        Args:
            max_message_bytes: the largest message the channel carries (0: any size).
            on_output: called when the lane gets a message while empty.

        Returns:
            The lane; the transport takes its messages with ``lossy_frame_to_send``.
        """
        limit = self._config.send_buffer_limit
        self._lossy = LossyLane(max_message_bytes, limit, on_output)
        return self._lossy

    def close_lossy_lane(self) -> None:
        """The lossy channel closed: its subscriptions' messages go on the reliable one."""
        if self._lossy is not None:
            self._lossy.clear()
            self._lossy = None

    @property
    def lossy_lane(self) -> LossyLane | None:
        """The lane of the transport's lossy channel, while it is open (D36)."""
        return self._lossy

    def lossy_frame_to_send(self, now: float | None = None) -> OutFrame | None:
        """Take the lossy lane's message that waited longest, or None (D36).

        ``now``: monotonic seconds; a message past its lifespan is not taken (D63).
        """
        lane = self._lossy
        if lane is None:
            return None
        frame = lane.pop(self._now if now is None else now)
        if frame is not None:
            self._outbox.taken_frames += 1
        return frame
