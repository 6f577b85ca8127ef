"""The per-client rules every protocol's session shares, defined once.

``SessionBase`` implements the connection runtime's side of ``contract.ServerSession``
for any protocol. It is made of three parts, each a module: the sender
(``sender.Sender``: the bounded outbox, its slow-consumer watch, the memory budget's
account, ``send_frames`` and the one hot-path entry ``queue_run``), the jobs it leaves
to its transport (``jobs.Jobs``) and its life (``lifecycle.Lifecycle``: the states and
the close it asks for). Here: the timers, the idle timeout (``idle.IdleWatch``), the
call book (``callbook.CallBook``), the lossy lane of a transport's second way out
(``lossy.LossyLane``, D36), the access gate, containment of a bug (``contain``: in a
frame's handler, a timer or a job, reported in the protocol's own words) and one log
line per kind of trouble. rosbridge's ``session.Session`` and the Foxglove protocol's
session are subclasses: each adds its ops (``handle_frame``, ``job_done``) and says
how its peer is told of a problem (``status_frames``), what it holds
(``holds_anything``) and what it releases (``release``). Limits come from one
``rules.ClientRules`` (docs/limits.md, "Per connection"), whichever protocol the
client speaks.

Nothing here awaits, sleeps or reads a clock; ``now`` is monotonic seconds
given by the caller.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, ClassVar

from ..errors import LimitError, RwtError
from ..levels import StatusLevel
from ..ratelog import EpisodeLog
from .access import Family, TopicUse, gate
from .backpressure import SlowConsumerWatch
from .callbook import CallBook
from .idle import IdleWatch
from .jobs import Jobs
from .lifecycle import Lifecycle, State
from .outbox import Outbox, SessionStats
from .sender import Sender
from .timers import Timer, TimerQueue

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from ..ports import ClientId, GraphPort
    from .commands import CloseConnection, Command
    from .jobs import Job
    from .lossy import LossyLane
    from .memory import MemoryBudget
    from .outbox import OutFrame
    from .rules import ClientRules

__all__ = ["SessionBase"]

logger = logging.getLogger("rwt.session")
_episodes = EpisodeLog(logger)  # a peer triggers these at will: one line per episode


class SessionBase(Sender, Lifecycle):
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

    protocol: ClassVar[str]
    """The protocol's name in logs (``event=connect ... protocol=foxglove``): each
    protocol's session names its own."""

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
        self.stats = SessionStats(self._outbox)
        self._watch = SlowConsumerWatch(self, self._outbox)
        self._commands: list[Command] = []
        self._timers = TimerQueue()
        self.calls = CallBook(self.call_at, config.max_pending_calls, config.call_timeout_s)
        """The calls this client has in flight (every protocol's: ``callbook``)."""
        self.jobs = Jobs()
        """The jobs it leaves to its transport, to run off the event loop (``jobs``)."""
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

    def receive_lossy_frame(self, frame: str | bytes, now: float, *, binary: bool = False) -> None:
        """Handle a frame that came on the transport's lossy channel (D36).

        A protocol without a lossy lane handles it as any frame (``receive_frame``).
        """
        self.receive_frame(frame, now, binary=binary)

    def finish_job(self, job: Job, result: object, now: float) -> None:
        """Take a job's outcome (``job_done``): what ``job.run()`` returned, or what it raised.

        Never raises: a job that failed, or a bug taking its outcome, is
        contained (``contain``) and the session goes on.
        """
        try:
            self.job_done(job, result, now)
        except Exception as exc:
            self.contain(exc, None, source="job")

    def add_job(self, job: Job, *, background: bool = False) -> None:
        """Leave ``job`` to the transport (``jobs``); ``background``: input goes on meanwhile.

        Without a transport that runs jobs (a bare session in a test), the caller
        runs them: ``jobs.take``/``jobs.take_background``, then ``finish_job``.
        """
        self.jobs.add(job, background=background)

    def drop_background_job(self, job: Job) -> bool:
        """Withdraw a waiting background job that sends a topic message, counted as dropped.

        Returns:
            Whether it was waiting (False: the transport took it already).
        """
        if not self.jobs.withdraw(job):
            return False
        self._outbox.dropped += 1
        return True

    def close(self) -> None:
        """The connection is gone: release everything it held in the graph. Idempotent."""
        if self._state is State.CLOSED:
            return
        self._move(State.CLOSED)
        try:
            self._timers.clear()
            self.calls.close()
            self.jobs.clear()
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

    def get_timer(self) -> float | None:
        """The monotonic time at which ``handle_timer`` must next be called, or None."""
        return None if self._state is State.CLOSED else self._timers.next_deadline()

    def handle_timer(self, now: float) -> None:
        """Run whatever was due at or before ``now`` (timers from ``get_timer``)."""
        if self._state is not State.CLOSED:
            self._now = max(self._now, now)
            self._timers.run_due(now, self._timer_failed)
            self.sweep_memory()

    # ---- what the transport and the protocol read -----------------------------------

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
    def authenticated(self) -> bool:
        """Whether ops were admitted (always, without an authenticator), even once closing."""
        return self._admitted

    # ---- what the protocol's handlers use ------------------------------------------

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
