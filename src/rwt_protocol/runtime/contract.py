"""What the connection runtime sees of a session, whatever protocol it speaks.

One pump (``rwt_transports.pump``) drives every protocol's session over every
transport: rosbridge's ``Session`` and the Foxglove WebSocket protocol's
``FoxgloveSession`` both implement ``ServerSession``, through the per-client
rules they share (``connection.SessionBase``: the bounded outbox, the slow-consumer
watch, timers, the idle timeout, the lifecycle, jobs). A third protocol does the
same and gets those rules, the server's admission, limits and flow control
without restating them (docs/architecture.md, "How to add a protocol").

The contract is sans-IO, after aioquic's connection: frames in with the time they
arrived (``receive_frame``), frames out within a byte budget (``frames_to_send``),
commands out (``commands_to_run``), one timer (``get_timer``/``handle_timer``),
jobs to run off the event loop (``jobs``, answered with ``finish_job``), and the
counts and gauges as one value (``stats``). A transport with a second, lossy way
out asks a session for ``LossySession`` (WebRTC's lossy data channel, D36).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from ..levels import StatusLevel
    from .commands import CloseCode, CloseConnection, Command
    from .jobs import Job, Jobs
    from .lossy import LossyLane
    from .memory import MemoryAccount
    from .outbox import OutFrame, SessionStats
    from .rules import ClientRules
    from .timers import Timer

__all__ = ["LossySession", "ServerSession", "WatchedSession"]


class WatchedSession(Protocol):
    """What the session's own watches (slow consumer, idle) see of it (``SessionBase``).

    They are parts of the session that hold it; typing them against this, not
    ``SessionBase``, keeps the runtime's modules free of an import circle.
    """

    @property
    def protocol(self) -> str:
        """The protocol's name in logs."""

    @property
    def client_id(self) -> str:
        """The connection's identity in the graph."""

    @property
    def config(self) -> ClientRules:
        """The connection's per-client rules."""

    def call_at(self, deadline: float, callback: Callable[[float], None]) -> Timer:
        """Run ``callback(now)`` once ``now >= deadline`` (monotonic seconds)."""

    def report(self, level: StatusLevel, text: str, op_id: str | int | None = None) -> None:
        """Tell the peer of a problem in its protocol's status."""

    def warn_dropping(self, text: str) -> None:
        """Tell the peer that its oldest topic messages are being dropped."""

    def dropping_over(self) -> None:
        """The episode of drops is over."""

    def holds_anything(self) -> bool:
        """Whether the client holds something in the graph (the idle rule)."""

    def request_close(self, code: CloseCode, reason: str, *, abort: bool = False) -> None:
        """Ask the transport to close after the frames queued so far."""


class ServerSession(Protocol):
    """One server-side connection's protocol state, as the connection runtime drives it.

    Sans-IO: no method blocks or does I/O; each says on its docstring what the driver
    (the transport's pump, ``rwt_transports.pump``) calls after it. In short: ``start``
    first; then, in any order the transport's events come, ``receive_frame``,
    ``handle_timer`` and ``finish_job``, each followed by ``commands_to_run``,
    ``get_timer`` and, while ``jobs.waiting``, ``jobs.take``; ``frames_to_send``
    whenever ``on_output`` was called, ``frames_sent`` once written; ``close`` last.
    """

    @property
    def protocol(self) -> str:
        """The protocol's name in logs (``event=connect ... protocol=foxglove``)."""

    @property
    def client_id(self) -> str:
        """The connection's identity in the graph (``ws:127.0.0.1:5000#3``)."""

    @property
    def peer(self) -> str:
        """The peer's address, ``host:port``."""

    @property
    def hold_budget_s(self) -> float:
        """Seconds this connection, as a reader, may be held for the outboxes it fills."""

    @property
    def water_marks(self) -> tuple[int, int]:
        """The outbox's (high, low) watermarks in bytes (input backpressure)."""

    @property
    def stats(self) -> SessionStats:
        """Its counts and gauges (queued, fill, dropped, taken...), read live: one value."""

    @property
    def jobs(self) -> Jobs:
        """The jobs it leaves to the transport: take them, run them, ``finish_job``.

        Set ``jobs.transport_runs`` and ``jobs.on_background`` before ``start``.
        """

    @property
    def memory(self) -> MemoryAccount | None:
        """The connection's account of the server's memory budget (D44), or None.

        A transport charges what it holds for the connection beyond the
        session's own (a WebRTC peer's input not read yet).
        """

    on_timer: Callable[[], None] | None
    """Called when a timer was set (``get_timer`` may say an earlier time); set by the
    pump. None: output's wake-up (``on_output``) is called instead."""

    wake_above_bytes: int
    """Fill (``stats.fill_bytes``) past which every output calls ``on_output``, not
    only one to an empty outbox: the high watermark, or lower while the pump waits to
    see the peer fall behind (``rwt_protocol.runtime.flow.WATCH_SHARE``). A protocol
    may wake more often."""

    def start(self, now: float) -> None:
        """The transport serves the connection from ``now`` (monotonic seconds).

        Call once, after setting ``jobs`` and ``on_timer`` and before any other method
        but the properties; then call ``get_timer`` (it may set one, the idle timer) and
        ``frames_to_send`` (a protocol may greet the peer, Foxglove's ``serverInfo``).
        """

    def receive_frame(self, frame: bytes | str, now: float, *, binary: bool = False) -> None:
        """Handle one whole incoming frame; never raises (a bug in it is contained).

        After it: ``commands_to_run`` (a close it asked for), ``jobs.take`` while
        ``jobs.waiting`` (before the next frame: input jobs keep the frames' order),
        and ``get_timer`` (it may have set an earlier one). Input that comes once
        ``closing`` is ignored.
        """

    def report(self, level: StatusLevel, text: str, op_id: str | int | None = None) -> None:
        """Tell the peer of a problem (a framing error) in its protocol's status."""

    def status_frames(
        self, level: StatusLevel, text: str, op_id: str | int | None = None
    ) -> Sequence[OutFrame]:
        """The frames of the protocol's status saying ``text``, not queued.

        The pump sends them as the last word before it cuts the connection for a
        bug of its own (the transport's; the session contains its own bugs).
        """

    def frames_to_send(
        self, max_bytes: int | None = None, now: float | None = None
    ) -> list[OutFrame]:
        """Take queued frames, oldest first, about ``max_bytes`` of payload (at least one).

        Call when ``on_output`` was called, until it returns none; write them, then call
        ``frames_sent`` (they count against the memory budget until then), then
        ``commands_to_run``: a close is queued after the frames it follows. ``now``:
        the monotonic time of the take, by which a message past its lifespan is
        dropped rather than sent (D63); None: the session's latest time.
        """

    def frames_sent(self) -> None:
        """The transport wrote the frames it took (they count as held until then, D44).

        Once per ``frames_to_send`` whose frames were written, before the next one.
        """

    def commands_to_run(self) -> list[Command]:
        """Take the commands queued for the transport (``CloseConnection``).

        After every input, timer, job and write; a ``CloseConnection`` is run once the
        frames queued before it are written (``abort``: at once).
        """

    def get_timer(self) -> float | None:
        """When ``handle_timer`` must next be called (monotonic seconds), or None.

        Ask again after each input, timer and job, and when ``on_timer`` is called: an
        earlier deadline replaces the one the driver waits for.
        """

    def handle_timer(self, now: float) -> None:
        """Run what was due at or before ``now``; never raises (a bug in it is contained).

        Call once ``get_timer``'s time has come; then as after ``receive_frame``.
        """

    def finish_job(self, job: Job, result: object, now: float) -> None:
        """Take a job's outcome: what ``run`` returned, or the exception it raised.

        Never raises: a failed job, or a bug taking its outcome, is contained. Then as
        after ``receive_frame``.
        """

    def request_close(self, code: CloseCode, reason: str, *, abort: bool = False) -> None:
        """Ask the transport to close after the frames queued so far."""

    def begin_shutdown(self) -> None:
        """The server is stopping: take no more input, release what the client holds.

        Then ``request_close`` (the server's going-away close) and write what is queued.
        """

    def close(self) -> None:
        """The connection is gone: release everything. Idempotent.

        Last: after it the driver calls nothing but the properties.
        """

    @property
    def close_request(self) -> CloseConnection | None:
        """The close this session asked for, if any."""

    @property
    def closing(self) -> bool:
        """Whether the session stopped taking input."""


@runtime_checkable
class LossySession(Protocol):
    """A session that sends on a transport's second, lossy way out too (D36).

    What a transport with a lossy channel (WebRTC's ``rosbridge-lossy``) asks a
    ``ServerSession`` for; every ``SessionBase`` is one (``lossy.LossyLane``).
    """

    def receive_lossy_frame(self, frame: bytes | str, now: float, *, binary: bool = False) -> None:
        """Handle one frame that came on the transport's lossy channel.

        Then as after ``ServerSession.receive_frame``.
        """

    def open_lossy_lane(self, max_message_bytes: int, on_output: Callable[[], None]) -> LossyLane:
        """Open the lane whose messages go on the transport's lossy channel.

        ``on_output`` is called when the lane has a message: then ``lossy_frame_to_send``.
        """

    def close_lossy_lane(self) -> None:
        """The lossy channel closed: its subscriptions' messages go on the reliable one."""

    def lossy_frame_to_send(self, now: float | None = None) -> OutFrame | None:
        """Take the lossy lane's message that waited longest, or None.

        ``now``: the take's monotonic time; a message past its lifespan is not taken (D63).
        """
