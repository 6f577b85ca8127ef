"""The sans-IO session: one peer's protocol state machine.

Inputs: ``receive_frame(frame, now)``, deliveries from the graph (through the
``TopicSink`` objects the session registers), ``handle_timer(now)``.
Outputs: ``frames_to_send()``, ``commands_to_run()``, ``get_timer()``.
Nothing here awaits, sleeps or reads a clock; ``now`` is monotonic seconds
given by the caller (STYLE.md, after aioquic).

Errors follow PROTOCOL-DECISIONS D1: every rejected op produces a ``status``
frame for this connection only (D29), filtered by the connection's level (D2),
and the session keeps serving. An exception that is not an ``RwtError`` is a bug:
it is logged and reported as an internal error, and the session still keeps
serving.

Before dispatch every op passes two gates: authentication (D23; with an
authenticator configured, the first op must be an admitted ``auth``, anything
else gets an error status and the connection is closed) and the access rules
(``AccessPolicy``: a denied op gets an error status and its failure reply, D4).

The outgoing side is bounded (D24): above ``send_buffer_limit`` the oldest topic
messages are dropped and counted, the first drop of each episode is reported as
a warning status, and a connection that stays over the limit without taking
any frames for ``send_timeout_s`` is closed with a reason.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum

from .access import AccessDeniedError, AccessPolicy
from .auth import Authenticator
from .codec import decode_json, encode_json, parse_object, peek_id
from .encoding import publish_frame
from .errors import RemoteProtocolError, RwtError
from .handlers import HANDLERS
from .handlers.providers import ProviderLink
from .levels import StatusLevel
from .ops import Auth, OpModel
from .ops.base import Compression
from .outbox import Outbox, OutFrame
from .ports import ClientId, GoalHandle, GraphPort, MessageEvent
from .replies import failure_reply
from .subscriptions import TopicSubscription
from .timers import Timer, TimerQueue

__all__ = ["CloseCode", "CloseConnection", "Command", "Session", "SessionConfig"]

logger = logging.getLogger("rwt.session")

MiB = 1024 * 1024


class CloseCode(IntEnum):
    """Why a session closes its connection, as RFC 6455 close codes (other transports log them)."""

    NORMAL = 1000
    GOING_AWAY = 1001  # server shutdown
    POLICY_VIOLATION = 1008  # authentication failed, slow consumer
    MESSAGE_TOO_BIG = 1009
    INTERNAL_ERROR = 1011  # keepalive timeout
    TRY_AGAIN_LATER = 1013  # too many connections


@dataclass(frozen=True)
class SessionConfig:
    """Per-connection settings.

    Attributes:
        status_level: the level a new connection starts at (D2, ``--status-level``).
        send_buffer_limit: bytes of outgoing frames kept queued before the oldest
            topic messages are dropped (D24, ``--send-buffer-limit``).
        send_timeout_s: seconds a connection may stay over ``send_buffer_limit``
            without taking any frame before it is closed (D24, ``--send-timeout``).
        access: the access rules (``--topics-glob`` and friends).
        authenticator: when set, the first op must be an ``auth`` it admits (D23).
        call_timeout_s: seconds a ``call_service`` without ``timeout`` waits before
            it fails (D16, ``--call-timeout``); None waits for ever.
    """

    status_level: StatusLevel = StatusLevel.ERROR
    send_buffer_limit: int = 16 * MiB
    send_timeout_s: float = 30.0
    access: AccessPolicy = field(default_factory=AccessPolicy)
    authenticator: Authenticator | None = None
    call_timeout_s: float | None = 30.0


@dataclass(frozen=True, slots=True)
class CloseConnection:
    """Command: close the connection (code per RFC 6455, reason for the peer and the log).

    ``abort`` means the peer is not reading: the transport need not wait for the
    close to be delivered before cutting the connection (D24).
    """

    code: CloseCode
    reason: str
    abort: bool = False


Command = CloseConnection
"""What a session asks its transport to do besides sending frames."""


class Session:
    """The protocol state of one server-side connection.

    Args:
        graph: the graph this session operates on.
        client_id: this connection's identity in the graph; unique per server.
        config: per-connection settings.
        on_output: called (synchronously, without arguments) whenever frames,
            commands or timers become available, so a transport can wake its
            writer and its timer task.
        peer: the peer's address (``"host:port"``), for the authenticator and logs.
    """

    def __init__(
        self,
        graph: GraphPort,
        client_id: ClientId,
        *,
        config: SessionConfig | None = None,
        on_output: Callable[[], None] | None = None,
        peer: str = "",
    ) -> None:
        self.graph = graph
        self.client_id = client_id
        self.peer = peer
        self.config = config or SessionConfig()
        self.status_level = self.config.status_level
        self.subscriptions: dict[str, TopicSubscription] = {}
        self.advertisements: dict[str, set[str | int | None]] = {}
        self.goals: dict[str | int | None, GoalHandle] = {}
        self.provider_link = ProviderLink(self)
        self._outbox = Outbox(self.config.send_buffer_limit)
        self._commands: list[Command] = []
        self.timers = TimerQueue()
        self._on_output = on_output
        self._closed = False
        self._closing = False  # input is ignored (close requested, or shutting down)
        self._close_request: CloseConnection | None = None  # once set, nothing more is sent
        self._authenticated = self.config.authenticator is None
        self._now = 0.0  # the latest monotonic time seen, for events without one
        self._full_timer: Timer | None = None  # set while over the send buffer limit
        self._takes = 0  # how many times the writer took frames (progress, D24)

    # ---- inputs -------------------------------------------------------------

    def receive_frame(self, frame: str | bytes, now: float) -> None:
        """Process one incoming frame (one JSON text).

        Never raises for anything the peer sent; see the module docstring.
        Frames arriving after the session asked to close are ignored.
        """
        if self._closed or self._closing:
            return
        self._now = now
        op_name: str | None = None
        op_id: str | int | None = None
        try:
            obj = decode_json(frame)
            op_id = peek_id(obj)
            op = parse_object(obj)
            op_name = op.op  # type: ignore[attr-defined]
            if not self._authenticated:
                self._authenticate(op)
            else:
                self.dispatch(op, now)
        except RwtError as exc:
            text = exc.message
            if not self._authenticated and "authentication" not in text:
                text = f"authentication required: {text}"
            self.report(exc.level, _prefixed(op_name, text), op_id)
            if not self._authenticated:
                self.request_close(CloseCode.POLICY_VIOLATION, "authentication required")
        except Exception:
            logger.exception("bug while handling a frame from %s", self.client_id)
            self.report(StatusLevel.ERROR, _prefixed(op_name, "internal error"), op_id)

    def dispatch(self, op: OpModel, now: float) -> None:
        """Check a validated op against the access rules, then run its handler.

        Raises:
            RwtError: the op was refused; the caller reports it. A denied
                ``call_service``/``send_action_goal`` is also answered (D4).
        """
        try:
            self.config.access.check(op)
        except AccessDeniedError as exc:
            logger.warning(
                "event=access_denied client=%s op=%s reason=%r",
                self.client_id,
                op.op,  # type: ignore[attr-defined]
                exc.message,
            )
            reply = failure_reply(op, f"{op.op}: {exc.message}")  # type: ignore[attr-defined]
            if reply is not None:
                self.send_op(reply)
            raise
        HANDLERS[type(op)](self, op, now)

    def _authenticate(self, op: OpModel) -> None:
        """The gate of D23: admit the connection on an accepted ``auth``, else close it.

        Raises:
            RemoteProtocolError: the op is not ``auth`` or was refused; the caller
                reports it and closes the connection.
        """
        if not isinstance(op, Auth):
            reply = failure_reply(op, "authentication required")
            if reply is not None:
                self.send_op(reply)
            self._auth_failed(f"first op was {op.op}")  # type: ignore[attr-defined]
            raise RemoteProtocolError("authentication required: the first op must be auth")
        authenticator = self.config.authenticator
        assert authenticator is not None  # only unauthenticated sessions get here
        try:
            admitted = authenticator(op, self.peer)
        except Exception:
            logger.exception("authenticator failed for %s", self.client_id)
            admitted = False
        if not admitted:
            self._auth_failed("refused by the authenticator")
            raise RemoteProtocolError("authentication failed")
        self._authenticated = True
        logger.info("event=auth_ok client=%s peer=%s level=%s", self.client_id, self.peer, op.level)
        self.report(StatusLevel.INFO, "auth: authenticated")

    def _auth_failed(self, reason: str) -> None:
        logger.warning(
            "event=auth_failed client=%s peer=%s reason=%r", self.client_id, self.peer, reason
        )

    def handle_timer(self, now: float) -> None:
        """Run whatever was due at or before ``now`` (timers from ``get_timer``)."""
        if not self._closed:
            self._now = max(self._now, now)
            self.timers.run_due(now)

    def request_close(self, code: CloseCode, reason: str, *, abort: bool = False) -> None:
        """Ask the transport to close: queue ``CloseConnection`` after the frames queued so far.

        Later input is ignored and later frames are not queued. Idempotent: only
        the first request counts.

        Args:
            code: the close code (WebSocket; logged on other transports).
            reason: why, for the peer and the log.
            abort: the peer is not reading (slow consumer): cut without waiting.
        """
        if self._closed or self._close_request is not None:
            return
        self._closing = True
        self._close_request = CloseConnection(code, reason, abort)
        logger.log(
            logging.DEBUG if code is CloseCode.NORMAL else logging.INFO,
            "event=closing client=%s code=%d reason=%r",
            self.client_id,
            code,
            reason,
        )
        self._commands.append(self._close_request)
        self._wake()

    @property
    def close_request(self) -> CloseConnection | None:
        """The close this session asked for, if any (also while the transport has it)."""
        return self._close_request

    def begin_shutdown(self) -> None:
        """The server is stopping: ignore further input and release what this client holds.

        Releasing first lets the graph answer callers waiting on this client
        (D4) while their connections can still send; the server then calls
        ``request_close(CloseCode.GOING_AWAY, ...)`` on every session.
        """
        if self._closed:
            return
        self._closing = True
        self.graph.release(self.client_id)

    def close(self) -> None:
        """The connection is gone: release everything it held in the graph. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self.timers.clear()
        self.subscriptions.clear()
        self.advertisements.clear()
        self.goals.clear()
        self.graph.release(self.client_id)

    # ---- outputs ------------------------------------------------------------

    def frames_to_send(self, max_bytes: int | None = None) -> list[OutFrame]:
        """Take the frames queued for the peer, oldest first.

        Args:
            max_bytes: take at most about this many payload bytes (at least one
                frame); None takes every frame. Taking frames counts as progress
                for the send timeout (D24).
        """
        frames = self._outbox.take(max_bytes)
        if frames:
            self._takes += 1
            caught_up = self._outbox.queued_bytes <= self._outbox.limit_bytes // 2
            if self._full_timer is not None and caught_up:
                self._full_timer.cancel()  # the episode is over: the peer caught up
                self._full_timer = None
        return frames

    def commands_to_run(self) -> list[Command]:
        """Take every command queued for the transport."""
        commands, self._commands = self._commands, []
        return commands

    def get_timer(self) -> float | None:
        """The monotonic time at which ``handle_timer`` must next be called, or None."""
        return None if self._closed else self.timers.next_deadline()

    @property
    def closed(self) -> bool:
        """Whether ``close`` was called."""
        return self._closed

    @property
    def closing(self) -> bool:
        """Whether the session stopped taking input (close requested or shutting down)."""
        return self._closing or self._closed

    @property
    def authenticated(self) -> bool:
        """Whether ops are served (always, without an authenticator)."""
        return self._authenticated

    @property
    def dropped_frames(self) -> int:
        """Topic messages dropped so far because the peer was too slow (D24)."""
        return self._outbox.dropped

    @property
    def queued_bytes(self) -> int:
        """Payload bytes waiting to be taken by the transport."""
        return self._outbox.queued_bytes

    # ---- helpers for handlers -------------------------------------------------

    def send(self, frame: OutFrame) -> None:
        """Queue a frame for the peer and wake the transport.

        Past the limit, the oldest topic messages go (D24); when undroppable
        frames alone exceed the limit the peer is not reading at all, and the
        connection is closed rather than let memory grow.
        """
        if self._closed or (self._close_request is not None):
            return
        limit = self._outbox.limit_bytes
        if not frame.droppable and self._outbox.undroppable_bytes > limit:
            self.request_close(
                CloseCode.POLICY_VIOLATION,
                f"send buffer overflow: over {limit} bytes unread",
                abort=True,
            )
            return
        was_empty = len(self._outbox) == 0
        dropped = self._outbox.dropped
        self._outbox.push(frame)
        full = self._outbox.dropped > dropped or self._outbox.over_limit
        if full and self._full_timer is None:
            self._start_full_episode(dropped)
        if was_empty:
            self._wake()

    def _start_full_episode(self, dropped_before: int) -> None:
        """The queue went over its limit: report once, and arm the send timeout (D24)."""
        timeout_s = self.config.send_timeout_s
        self._full_timer = self.timers.schedule(
            self._now + timeout_s, self._make_full_check(self._takes)
        )
        logger.warning(
            "event=slow_consumer client=%s limit_bytes=%d dropped_total=%d",
            self.client_id,
            self._outbox.limit_bytes,
            dropped_before,
        )
        self.report(
            StatusLevel.WARNING,
            f"dropping the oldest topic messages: this connection reads slower than they "
            f"arrive (send buffer limit {self._outbox.limit_bytes} bytes)",
        )
        self._wake()  # the timer task must learn the new deadline

    def _make_full_check(self, takes: int) -> Callable[[float], None]:
        def check(now: float) -> None:
            if self._takes != takes:  # still full, but the peer is reading: look again later
                self._full_timer = self.timers.schedule(
                    now + self.config.send_timeout_s, self._make_full_check(self._takes)
                )
                return
            self._full_timer = None
            self.request_close(
                CloseCode.POLICY_VIOLATION,
                f"slow consumer: send buffer over {self._outbox.limit_bytes} bytes "
                f"for {self.config.send_timeout_s:g} s",
                abort=True,
            )

        return check

    def _wake(self) -> None:
        if self._on_output is not None:
            self._on_output()

    def send_op(
        self,
        message: dict[str, object],
        *,
        compression: Compression = "none",
        fragment_size: int | None = None,
    ) -> None:
        """Queue an op that must not be dropped (responses, results, status, requests).

        Args:
            message: the op as a dict, ``op`` first; values in the internal form.
            compression: the encoding the request asked for (``call_service`` and
                ``send_action_goal`` replies, spec 3.3.8/3.3.12; encodings: issue 4).
            fragment_size: split the encoded op into ``fragment`` ops above this many
                characters (PROTOCOL-DECISIONS D19; issue 4).
        """
        self.send(OutFrame(encode_json(message)))

    def report(self, level: StatusLevel, text: str, op_id: str | int | None = None) -> None:
        """Send a ``status`` frame if this connection's level admits it (spec 3.2, D1-D3)."""
        if not self.status_level.admits(level):
            return
        status: dict[str, object] = {"op": "status", "level": level.wire, "msg": text}
        if op_id is not None:
            status["id"] = op_id
        self.send_op(status)

    def deliver(self, subscription: TopicSubscription, event: MessageEvent) -> None:
        """Queue one topic message for the peer, encoded once per spelling."""
        self._now = max(self._now, event.now)
        self.send(publish_frame(subscription, event))


def _prefixed(op_name: str | None, text: str) -> str:
    if op_name is None or text.startswith(f"{op_name}: "):
        return text
    return f"{op_name}: {text}"
