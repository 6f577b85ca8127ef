"""The per-client rules every protocol's session shares, defined once.

``SessionBase`` implements the connection runtime's side of ``contract.ServerSession``
for any protocol: the lifecycle (``lifecycle.State``), the bounded outbox
(``outbox.Outbox``: bytes, and topic messages by count where the protocol bounds
them), the slow-consumer watch (``backpressure.SlowConsumerWatch``: the first
drop of an episode told, a peer that stays over its limit without reading
closed after ``send_timeout_s``, undroppable frames past the limit close it
too), the timers, the idle timeout (``idle.IdleWatch``), jobs the transport runs
off the event loop, containment of a bug (``contain``: in a frame's handler, a
timer or a job, reported in the protocol's own words), one log line per
kind of trouble, and the connection's account of the server's memory budget
(``memory.MemoryAccount``, D44: what its outbox and the messages being prepared
for it hold, and the slow-consumer rule while the budget is full). rosbridge's
``session.Session`` and the Foxglove protocol's session are subclasses: each
adds its ops (``handle_frame``, ``job_done``) and says how its peer is told of a
problem (``status_frames``), what it holds (``holds_anything``) and what it
releases (``release``). Limits come
from one ``rules.ClientRules`` (docs/limits.md, "Per connection"), whichever
protocol the client speaks.

Nothing here awaits, sleeps or reads a clock; ``now`` is monotonic seconds
given by the caller.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, ClassVar

from ..errors import LimitError, RwtError
from ..levels import StatusLevel
from ..ratelog import EpisodeLog
from .access import Family, TopicUse, gate
from .backpressure import SlowConsumerWatch
from .callbook import CallBook
from .commands import CloseCode, CloseConnection, Command
from .idle import IdleWatch
from .lifecycle import State, advance
from .lossy import LossyLane
from .memory import PRESSURE_FLOOR_BYTES
from .outbox import Outbox, OutFrame, QueueRule
from .timers import Timer, TimerQueue

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from ..ports import ClientId, GraphPort, MessageEvent
    from .contract import Job
    from .memory import MemoryAccount, MemoryBudget
    from .rules import ClientRules

__all__ = ["SessionBase"]

logger = logging.getLogger("rwt.session")
_episodes = EpisodeLog(logger)  # a peer triggers these at will: one line per episode


class SessionBase:
    """One client's connection under the server's per-client rules (the module's text).

    Args:
        graph: the graph the session operates on.
        client_id: the connection's identity in the graph; unique per server.
        config: the per-client rules (``rules.ClientRules``; docs/limits.md).
        on_output: called (synchronously, without arguments) whenever frames or
            commands become available or a timer is set, so the transport can
            wake its writer and look at ``get_timer`` again.
        peer: the peer's address (``host:port``), for logs.
        on_closed: called once with ``client_id`` when the session closes.
        authenticating: the session starts in ``State.AUTHENTICATING`` (rosbridge's
            ``auth`` op is due first, D23) rather than ``OPEN``.
        max_messages: topic messages the outbox holds by count (None: bytes only).
        memory: the server's memory budget the connection is charged to (D44);
            None: its own bounds alone.
    """

    protocol: ClassVar[str] = "rosbridge"
    """The protocol's name in logs (``event=connect ... protocol=foxglove``)."""

    wakes_each_run: ClassVar[bool] = False
    """Whether ``queue_run`` wakes the transport after every run, not only when the
    outbox was empty or is past ``wake_above_bytes`` (``ServerSession``: a protocol may
    wake more often). A Foxglove client's bursts are gathered into fewer writes so
    (``rwt_transports.gather``: output during a gathering marks a burst)."""

    def __init__(
        self,
        graph: GraphPort,
        client_id: ClientId,
        *,
        config: ClientRules,
        on_output: Callable[[], None] | None = None,
        peer: str = "",
        on_closed: Callable[[ClientId], None] | None = None,
        authenticating: bool = False,
        max_messages: int | None = None,
        memory: MemoryBudget | None = None,
    ) -> None:
        self._graph = graph
        self._client_id = client_id
        self._peer = peer
        self._config = config
        self._outbox = Outbox(config.send_buffer_limit, max_messages=max_messages)
        self._memory = None if memory is None else memory.account(self._memory_pressure)
        self._outbox.account = self._memory
        self._pending_bytes = 0  # topic messages being made for the outbox (png, ``pngout``)
        self._watch = SlowConsumerWatch(self, self._outbox)
        self._commands: list[Command] = []
        self._timers = TimerQueue()
        self.calls = CallBook(self.call_at, config.max_pending_calls, config.call_timeout_s)
        """The calls this client has in flight (every protocol's: ``callbook``)."""
        self._jobs: list[Job] = []  # input jobs: the reader waits for each
        self._background: list[Job] = []  # the reader goes on meanwhile
        self._runs_jobs = False  # set by a transport that runs the jobs (``run_jobs``)
        self.on_job: Callable[[], None] | None = None
        self.on_timer: Callable[[], None] | None = None
        timeout = config.idle_timeout_s
        self._idle = IdleWatch(self, timeout) if timeout else None
        self._on_output = on_output
        self.wake_above_bytes = self._outbox.high_water_bytes
        """Fill past which each output wakes the transport (``ServerSession``): the
        high watermark, or lower while the transport watches for the peer to fall behind."""
        self._on_closed = on_closed
        self._state = State.AUTHENTICATING if authenticating else State.OPEN
        self._sends = True  # ``_state.sends``, kept by ``_move`` for the per-message paths
        self._admitted = self._state is State.OPEN  # ops were served
        self._close_request: CloseConnection | None = None  # set on entering CLOSING
        self._now = 0.0  # the latest monotonic time seen, for output without one
        self._logged: set[str] = set()  # kinds of trouble already logged (one line each)
        self._lossy: LossyLane | None = None  # a transport's lossy channel (D36)
        self.request_scoped = False
        """The session is one request of a front end without connections (an HTTP
        request, a 2026-07-28 MCP request), not a connection: its end is not its
        client leaving, for the safety envelope's dead-man (``GraphPort.release``, D68)."""

    # ---- what each protocol says -------------------------------------------------

    def status_frames(
        self, level: StatusLevel, text: str, op_id: str | int | None = None
    ) -> Sequence[OutFrame]:
        """The frames of the protocol's status saying ``text``, not queued (each protocol's).

        Empty where the protocol says nothing at ``level``. The pump sends them
        as the last word before it cuts a connection for a bug of its own.
        """
        raise NotImplementedError

    def report(self, level: StatusLevel, text: str, op_id: str | int | None = None) -> None:
        """Tell the peer of a problem or an event in its protocol's status (``status_frames``)."""
        frames = self.status_frames(level, text, op_id)
        if frames:
            self.send_frames(frames)

    def handle_frame(self, frame: str | bytes, now: float, binary: bool) -> None:
        """Handle one whole incoming frame (each protocol's; ``receive_frame`` contains it).

        Raises:
            RwtError: the peer's frame was refused: reported at its level.
            Exception: a bug: reported as ``internal error`` (``contain``).
        """
        raise NotImplementedError

    def holds_anything(self) -> bool:
        """Whether the client holds something in the graph it waits on or serves (idle rule)."""
        raise NotImplementedError

    def release(self) -> None:
        """Drop what the client holds in the graph (it leaves, or the server stops)."""
        self._graph.release(self._client_id, ended=not self.request_scoped)

    def warn_dropping(self, text: str) -> None:
        """Tell the peer that its oldest topic messages are being dropped (an episode began)."""
        self.report(StatusLevel.WARNING, text)

    def dropping_over(self) -> None:
        """The episode of drops is over: the transport caught up (nothing to say by default)."""

    def taken(self, frames: list[OutFrame]) -> None:
        """The transport took ``frames`` (a protocol that tracks its frames looks here)."""

    def job_done(self, job: Job, result: object, now: float) -> None:
        """Take the outcome of a job the protocol made (each protocol's; ``finish_job`` calls it).

        A protocol handles the jobs it knows and leaves the others here.

        Raises:
            Exception: ``result``, when the job failed: ``finish_job`` contains it.
        """
        if isinstance(result, Exception):
            raise result

    # ---- the transport's side ------------------------------------------------------

    def start(self, now: float) -> None:
        """The transport serves the connection from ``now``: time-driven rules count from it."""
        self._now = now
        if self._idle is not None:
            self._idle.start(now)

    def received(self, now: float) -> None:
        """Input came at ``now`` (the idle rule counts from the last); every frame calls it."""
        self._now = now
        if self._idle is not None:
            self._idle.last_input = now

    def take_job(self) -> Job | None:
        """The oldest input job (the reader waits for it before its next frame), or None."""
        return self._jobs.pop(0) if self._jobs else None

    @property
    def has_jobs(self) -> bool:
        """Whether input jobs wait: the transport runs them before the next frame."""
        return bool(self._jobs)

    def take_background_job(self) -> Job | None:
        """The oldest background job, or None; the reader goes on while it runs."""
        return self._background.pop(0) if self._background else None

    def add_job(self, job: Job, *, background: bool = False) -> None:
        """Leave ``job`` to the transport (``run_jobs``); ``background``: input goes on meanwhile.

        Without a transport that runs jobs (a bare session in a test), the caller
        runs them: ``take_job``/``take_background_job``, then ``finish_job``.
        """
        if background:
            self._background.append(job)
            if self.on_job is not None:
                self.on_job()
        else:
            self._jobs.append(job)

    def drop_background_job(self, job: Job) -> bool:
        """Withdraw a waiting background job that sends a topic message, counted as dropped.

        Returns:
            Whether it was waiting (False: the transport took it already).
        """
        try:
            self._background.remove(job)
        except ValueError:
            return False
        self._outbox.dropped += 1
        return True

    def run_jobs(self) -> None:
        """The transport runs the jobs from now on, off its event loop."""
        self._runs_jobs = True

    def request_close(self, code: CloseCode, reason: str, *, abort: bool = False) -> None:
        """Ask the transport to close: queue ``CloseConnection`` after the frames queued so far.

        Later input is ignored and later frames are not queued. Idempotent: only
        the first request counts.

        Args:
            code: the close code (WebSocket; logged on other transports).
            reason: why, for the peer and the log.
            abort: the peer is not reading (slow consumer): cut without waiting.
        """
        if self._state in (State.CLOSING, State.CLOSED):
            return
        self._move(State.CLOSING)
        self._close_request = CloseConnection(code, reason, abort)
        logger.log(
            logging.DEBUG if code is CloseCode.NORMAL else logging.INFO,
            "event=closing client=%s code=%d reason=%r",
            self._client_id,
            code,
            reason,
        )
        self._commands.append(self._close_request)
        self._wake()

    def begin_shutdown(self) -> None:
        """The server is stopping: ignore further input and release what this client holds.

        Releasing first lets the graph answer callers waiting on this client
        (D4) while their connections can still send; the server then calls
        ``request_close(CloseCode.GOING_AWAY, ...)`` on every session.
        """
        if self._state is State.CLOSED:
            return
        if self._state.takes_input:
            self._move(State.DRAINING)
        self.release()

    def close(self) -> None:
        """The connection is gone: release everything it held in the graph. Idempotent."""
        if self._state is State.CLOSED:
            return
        self._move(State.CLOSED)
        try:
            self._timers.clear()
            self.calls.close()
            self._jobs.clear()
            self._background.clear()
            self._outbox.take()  # what a peer that left never read goes now
            if self._memory is not None:
                self._memory.close()
                if self._memory.budget.sweeper is self:  # another session takes it over
                    self._memory.budget.sweeper = None
            self.close_lossy_lane()
            self.release()
        finally:  # even if releasing raised, the owner forgets the connection
            if self._on_closed is not None:
                self._on_closed(self._client_id)

    def receive_lossy_frame(self, frame: str | bytes, now: float, *, binary: bool = False) -> None:
        """Handle a frame that came on the transport's lossy channel (D36).

        A protocol without a lossy lane handles it as any frame (``receive_frame``).
        """
        self.receive_frame(frame, now, binary=binary)

    def receive_frame(self, frame: str | bytes, now: float, *, binary: bool = False) -> None:
        """Handle one whole incoming frame (``handle_frame``); never raises.

        Frames after the session stopped taking input are ignored. What the
        protocol's handler raises is contained (``contain``): the peer is told
        in its protocol's words and the session goes on (docs/limits.md,
        containment).
        """
        if not self._state.takes_input:
            return
        self.received(now)
        try:
            self.handle_frame(frame, now, binary)
        except Exception as exc:  # the protocol's handler let it out: contained here
            self.contain(exc, None)

    def finish_job(self, job: Job, result: object, now: float) -> None:
        """Take a job's outcome (``job_done``): what ``job.run()`` returned, or what it raised.

        Never raises: a job that failed, or a bug taking its outcome, is
        contained (``contain``) and the session goes on.
        """
        try:
            self.job_done(job, result, now)
        except Exception as exc:
            self.contain(exc, None, source="job")

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

    def commands_to_run(self) -> list[Command]:
        """Take every command queued for the transport."""
        commands, self._commands = self._commands, []
        return commands

    def get_timer(self) -> float | None:
        """The monotonic time at which ``handle_timer`` must next be called, or None."""
        return None if self._state is State.CLOSED else self._timers.next_deadline()

    def handle_timer(self, now: float) -> None:
        """Run whatever was due at or before ``now`` (timers from ``get_timer``)."""
        if self._state is not State.CLOSED:
            self._now = max(self._now, now)
            self._timers.run_due(now, self._timer_failed)
            self.sweep_memory()

    # ---- what the transport reads --------------------------------------------------

    @property
    def close_request(self) -> CloseConnection | None:
        """The close this session asked for, if any (also while the transport has it)."""
        return self._close_request

    @property
    def now(self) -> float:
        """The latest monotonic time the session was given, in seconds (0 before any input)."""
        return self._now

    @property
    def graph(self) -> GraphPort:
        """The graph this session operates on."""
        return self._graph

    @property
    def client_id(self) -> ClientId:
        """This connection's identity in the graph."""
        return self._client_id

    @property
    def peer(self) -> str:
        """The peer's address, ``host:port`` (empty when unknown)."""
        return self._peer

    @property
    def config(self) -> ClientRules:
        """This connection's settings."""
        return self._config

    @property
    def hold_budget_s(self) -> float:
        """Seconds this connection, as a reader, may be held (``ClientRules.hold_budget_s``)."""
        return self._config.hold_budget_s

    @property
    def state(self) -> State:
        """Where the connection is in its life (``lifecycle.State``, its moves in one table)."""
        return self._state

    @property
    def closed(self) -> bool:
        """Whether ``close`` was called (``state`` is CLOSED)."""
        return self._state is State.CLOSED

    @property
    def closing(self) -> bool:
        """Whether the session stopped taking input (close requested, shutting down, closed)."""
        return not self._state.takes_input

    @property
    def authenticated(self) -> bool:
        """Whether ops were admitted (always, without an authenticator), even once closing."""
        return self._admitted

    @property
    def dropped_frames(self) -> int:
        """Topic messages dropped so far because the peer was too slow (D24)."""
        return self._outbox.dropped

    @property
    def expired_messages(self) -> int:
        """Of ``dropped_frames``, messages a newer one outdated (``Outbox.expired``)."""
        return self._outbox.expired

    @property
    def topic_messages(self) -> int:
        """Topic messages queued for the peer so far, those dropped since included."""
        return self._outbox.topic_messages

    @property
    def taken_frames(self) -> int:
        """Frames the transport took from the queue so far (topic messages and replies)."""
        return self._outbox.taken_frames

    @property
    def queued_bytes(self) -> int:
        """Payload bytes waiting to be taken by the transport."""
        return self._outbox.queued_bytes

    @property
    def queued_reply_bytes(self) -> int:
        """Bytes of queued frames that are never dropped (replies, statuses; D24)."""
        return self._outbox.undroppable_bytes

    @property
    def fill_bytes(self) -> int:
        """How full the outbox is for the watermarks, ``pending_bytes`` included."""
        return self._outbox.fill_bytes + self._pending_bytes

    @property
    def pending_bytes(self) -> int:
        """Bytes of topic messages being made for the outbox off the loop (png, ``pngout``)."""
        return self._pending_bytes

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

    # ---- what the protocol's handlers use ------------------------------------------

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
        if lifespan > 0 or expires != math.inf:
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
        self.shed_topic_messages(max(0, outbox.queued_bytes + self._pending_bytes - excess))
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

    def call_at(self, deadline: float, callback: Callable[[float], None]) -> Timer:
        """Run ``callback(now)`` from ``handle_timer`` once ``now >= deadline``.

        Tells the transport (``on_timer``, else ``on_output``) so that it sees the
        new deadline in ``get_timer``.
        """
        timer = self._timers.schedule(deadline, callback)
        if self._state is not State.CLOSED:
            if self.on_timer is not None:
                self.on_timer()
            else:
                self._wake()
        return timer

    def check_cap(self, count: int, cap: int, what: str) -> None:
        """Refuse an op that would hold more than ``cap`` of ``what`` (docs/limits.md).

        Raises:
            LimitError: ``count`` (what the connection holds now) reached ``cap``.
        """
        if count >= cap:
            raise LimitError(f"{what}: this connection holds {cap} already (the server's limit)")

    def require_access(
        self, family: Family, name: str, op: str, use: TopicUse | None = None
    ) -> None:
        """The access gate of every protocol: refuse what the access rules deny.

        The rules are the server's (``ClientRules.access``: ``--topics-glob``
        and friends); a refusal passes the one access gate (``access.gate``) and
        its one log line (``event=access_denied``, once per episode, repeats
        counted), naming the glob that refused (``glob=topics_sub_glob``, D50).

        Args:
            family: what ``name`` is (topic, service, action, parameter).
            name: the resolved name.
            op: what the client asked for, for the log (``subscribe``, ``advertise``).
            use: for a topic, publishing or subscribing (``--topics-pub-glob``,
                ``--topics-sub-glob``); None checks it as a listing would.

        Raises:
            AccessDeniedError: ``name`` is outside the rules.
        """
        gate(
            self._config.access, family, name, client=self._client_id, op=op, use=use, now=self._now
        )

    def _wake(self) -> None:
        if self._on_output is not None:
            self._on_output()

    def _move(self, target: State) -> None:
        """Change ``state`` along ``lifecycle.TRANSITIONS``; LocalProtocolError otherwise."""
        self._state = advance(self._state, target)
        self._sends = self._state.sends

    def _log_once(self, kind: str) -> bool:
        """Whether trouble of ``kind`` is new on this connection (so that one line is logged)."""
        if kind in self._logged:
            return False
        self._logged.add(kind)
        return True

    def _timer_failed(self, exc: Exception) -> None:
        """A timer's callback raised (``handle_timer``): contained as any bug."""
        self.contain(exc, None, source="timer")

    def contain(
        self,
        exc: Exception,
        what: str | None,
        op_id: str | int | None = None,
        *,
        source: str = "frame",
    ) -> None:
        """The one containment point: what a frame, a timer or a job raised (docs/limits.md).

        An ``RwtError`` is reported at its level with its message; anything else
        is a bug (``_bug``). Either way the peer hears it in its protocol's words
        (``report``) and the session goes on, whichever protocol it speaks.

        Args:
            exc: what was raised.
            what: the op or request it was for, as the peer's status names it
                (``set_level: internal error``); None: none.
            op_id: the request's id, for the status.
            source: ``frame``, ``timer`` or ``job``, for the log.
        """
        if isinstance(exc, RwtError):
            text = exc.message if what is None else f"{what}: {exc.message}"
            try:
                self.report(exc.level, text, op_id)
            except Exception:  # the report is total; a bug there must not reach the transport
                logger.debug("cannot report to %s", self._client_id, exc_info=True)
            return
        self._bug(what, op_id, source=source, exc=exc)

    def _bug(
        self,
        what: str | None,
        op_id: str | int | None = None,
        *,
        source: str = "frame",
        exc: Exception | None = None,
    ) -> None:
        """Report a bug: ``exc``, or the exception being handled, which is not an ``RwtError``.

        Logged with its traceback once per connection (then at debug level); the
        peer gets an ``internal error`` status for ``what`` and the session goes
        on (docs/limits.md, containment), whichever protocol it speaks.
        """
        exc_info: Exception | bool = True if exc is None else exc
        level = logging.ERROR if self._log_once("bug") else logging.DEBUG
        logger.log(
            level, "bug while handling a %s from %s", source, self._client_id, exc_info=exc_info
        )
        try:
            text = "internal error" if what is None else f"{what}: internal error"
            self.report(StatusLevel.ERROR, text, op_id)
        except Exception:  # the report is total; a bug there must still not reach the transport
            logger.debug("cannot report a bug to %s", self._client_id, exc_info=True)
