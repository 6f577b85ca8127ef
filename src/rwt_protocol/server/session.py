"""The sans-IO session: one peer's protocol state machine.

Inputs: ``receive_frame(frame, now)``, deliveries from the graph (through the
``TopicSink`` objects the session registers), ``handle_timer(now)``.
Outputs: ``frames_to_send()``, ``commands_to_run()``, ``get_timer()``.
Nothing here awaits, sleeps or reads a clock; ``now`` is monotonic seconds
given by the caller (after aioquic).

The connection's life is one ``lifecycle.State`` (``state``), moved only along
the table ``lifecycle.TRANSITIONS``; what it holds in the graph is one
``holdings.Holdings`` (``holdings``). Handlers see the session through
``handlers.HandlerContext`` and change it only through methods: every public
attribute is read-only.

Errors follow D1: every rejected op produces a ``status``
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
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..auth import AUTH_CHALLENGE_ID, new_challenge
from ..codecs.cbor import decode_cbor
from ..codecs.json import decode_json, decode_publish, parse_object, peek_id
from ..errors import GraphError, LimitError, RwtError
from ..framing.fragments import FragmentBudget, Reassembler
from ..levels import StatusLevel
from ..ops import OpModel, PublishView, Status
from ..ops.base import Compression
from ..shortcuts import enabled
from . import gates
from .access import AccessPolicy
from .backpressure import SlowConsumerWatch
from .commands import CloseCode, CloseConnection, Command
from .compat import Compat, initial_status_level
from .encoding import EncodeFailure, safe_op_frames, safe_publish_frames
from .handlers import HANDLERS
from .handlers.providers import ProviderLink
from .holdings import Holdings
from .idle import IdleWatch
from .inflate import InflateJob, TokenBucket
from .lifecycle import State, advance
from .outbox import Outbox, OutFrame
from .timers import Timer, TimerQueue

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from ..auth import Authenticator
    from ..codecs.png import PendingPng
    from ..ports import ClientId, GraphPort, MessageCodec, MessageEvent
    from .subscriptions import TopicSubscription

__all__ = ["CloseCode", "CloseConnection", "Command", "Session", "SessionConfig", "State"]

logger = logging.getLogger("rwt.session")

MiB = 1024 * 1024

HOLD_BUDGET_S = 5.0
"""Default ``SessionConfig.hold_budget_s``: seconds a publisher (or caller) may be held
back by the congested connections it fills, in all, regaining a tenth of a second a
second (docs/limits.md, input backpressure).

Long enough for a subscriber that reads to take a burst whole (B19: 200,000
messages, the publisher held about half of the time), short against a stream
a subscriber cannot keep up with: after it, that subscriber loses its own
oldest messages and the publisher and every other subscriber go at full rate.
"""


_PUBLISH_DECODE = enabled("publish-decode")  # docs/shortcuts.md


@dataclass(frozen=True)
class SessionConfig:
    """Per-connection settings.

    Attributes:
        status_level: the level a new connection starts at (D2, ``--status-level``).
        compat: whose behaviour the connection follows where rwt and rosbridge_suite
            differ (``compat.Compat``, ``--compat``; docs/differences.md).
        send_buffer_limit: bytes of outgoing frames kept queued before the oldest
            topic messages are dropped (D24, ``--send-buffer-limit``); each frame
            counts its payload plus ``outbox.FRAME_OVERHEAD_BYTES``, so the
            limit bounds the memory a stalled peer holds.
        send_timeout_s: seconds a connection may stay over ``send_buffer_limit``
            without taking any frame before it is closed (D24, ``--send-timeout``).
        hold_budget_s: seconds this connection, as a reader, may be held back
            by the congested outboxes it fills (input backpressure,
            ``--hold-budget``), in all, whoever it waits for, regaining it
            slowly; a connection it was waiting for when it ran out is slow and
            loses its own oldest topic messages (D24) instead (docs/limits.md).
        access: the access rules (``--topics-glob`` and friends).
        authenticator: when set, the first op must be an ``auth`` it admits (D23).
        auth_challenge: with an authenticator, send each connection a challenge
            first (a ``status`` with ``id`` ``auth_challenge`` and the nonce as
            ``msg``) and admit only an ``auth`` whose ``rand`` is that nonce
            (``--auth-bind-connection``, D31); the authenticator then checks a
            MAC that covers ``rand`` (``RosauthVerifier(bound=True)``).
        max_message_size: the largest message reassembled from ``fragment`` or
            ``png`` parts, and the most their pending parts may hold at once,
            bytes (D19, D24, ``--max-message-size``). A ``RosbridgeServer`` sets
            it from its ``ServerConfig.max_message_size``, the one limit of all
            its transports.
        max_pending_fragments: messages whose parts are still arriving, at most
            (D19, ``--max-pending-fragments``).
        fragment_timeout_s: seconds without a new part after which an incomplete
            message is dropped (D19, ``--fragment-timeout``; rosbridge's 600 s).
        max_queue_length: the most messages a throttled subscription queues; a
            larger ``queue_length`` is capped with a warning (D12, D24,
            ``--max-queue-length``).
        call_timeout_s: seconds a ``call_service`` without ``timeout`` waits before
            it fails (D16, ``--call-timeout``); None waits for ever.
        max_subscriptions: topics one connection may subscribe to at once
            (``--max-subscriptions``); the next ``subscribe`` gets an error status.
        max_advertisements: topics, services and actions one connection may
            advertise at once, together (``--max-advertisements``).
        max_ids_per_topic: ``subscribe`` or ``advertise`` ids one connection may
            hold on one topic (merged per D11).
        max_pending_calls: ``call_service`` ops of one connection waiting for their
            reply (``--max-pending-calls``); the next is answered ``result: false``.
        max_pending_goals: ``send_action_goal`` ops of one connection waiting for
            their result (``--max-pending-goals``); the next gets a failed result.
        idle_timeout_s: seconds after which a connection whose peer sent nothing and
            that holds nothing (no subscription, advertisement, offer, goal, pending
            call or goal, incomplete message) is closed (``idle.IdleWatch``); None:
            never. A ``RosbridgeServer`` sets it from ``ServerConfig.idle_timeout_s``
            for WebSocket and TCP connections (``--idle-timeout``).
        png_inflate_rate: bytes a second of ``png`` images one connection may have
            inflated, after a burst of ``max_message_size`` (``--png-inflate-rate``;
            ``inflate.TokenBucket``): past it, its later ``png`` ops wait.
        All caps are listed with what a client sees in docs/limits.md.
    """

    status_level: StatusLevel = StatusLevel.ERROR
    compat: Compat = Compat.RWT
    send_buffer_limit: int = 16 * MiB
    send_timeout_s: float = 30.0
    hold_budget_s: float = HOLD_BUDGET_S
    access: AccessPolicy = field(default_factory=AccessPolicy)
    authenticator: Authenticator | None = None
    auth_challenge: bool = False
    max_message_size: int = 10 * MiB
    max_pending_fragments: int = 16
    fragment_timeout_s: float = 600.0
    max_queue_length: int = 100
    call_timeout_s: float | None = 30.0
    max_subscriptions: int = 1000
    max_advertisements: int = 1000
    max_ids_per_topic: int = 100
    max_pending_calls: int = 1000
    max_pending_goals: int = 1000
    png_inflate_rate: int = 8 * MiB
    idle_timeout_s: float | None = None


class Session:
    """The protocol state of one server-side connection.

    Args:
        graph: the graph this session operates on.
        client_id: this connection's identity in the graph; unique per server.
        config: per-connection settings.
        on_output: called (synchronously, without arguments) whenever frames or
            commands become available or a timer is set, so a transport can wake
            its writer and look at ``get_timer`` again.
        peer: the peer's address (``"host:port"``), for the authenticator and logs.
        on_closed: called once with ``client_id`` when the session closes (after
            it released what it held, even if releasing raised), so its owner
            can forget the connection.
        fragment_budget: the server-wide bound on incomplete ``fragment``/``png``
            parts that every connection's parts are also charged to
            (``--max-fragment-memory``); None: only this connection's bound.
        auth_nonce: with ``config.auth_challenge``, the connection's challenge when
            the transport already gave it to the client (UDP sends it with the
            address validation, before the first op); the session then sends
            none. None: the session makes one and sends it first.
        authenticated: the transport already admitted the connection with the
            authenticator (a Foxglove client's URL token, ``auth.auth_from_query``):
            the session starts open and sends no challenge.

    The client end is ``client.ClientSession``: the same ops, from the other end.
    """

    def __init__(
        self,
        graph: GraphPort,
        client_id: ClientId,
        *,
        config: SessionConfig | None = None,
        on_output: Callable[[], None] | None = None,
        peer: str = "",
        on_closed: Callable[[ClientId], None] | None = None,
        fragment_budget: FragmentBudget | None = None,
        auth_nonce: str | None = None,
        authenticated: bool = False,
    ) -> None:
        self._graph = graph
        self._client_id = client_id
        self._peer = peer
        self._config = config or SessionConfig()
        self._status_level = initial_status_level(self._config.compat, self._config.status_level)
        self._holdings = Holdings()
        self._provider_link = ProviderLink(self)
        self._outbox = Outbox(self._config.send_buffer_limit)
        self._watch = SlowConsumerWatch(self, self._outbox)
        self._commands: list[Command] = []
        self._timers = TimerQueue()
        self._fragments = Reassembler(
            max_bytes=self._config.max_message_size,
            max_pending=self._config.max_pending_fragments,
            timeout_s=self._config.fragment_timeout_s,
            shared=fragment_budget,
        )
        self._fragment_timer: Timer | None = None
        self._inflate_budget = TokenBucket(
            self._config.png_inflate_rate, max(self._config.max_message_size, 1)
        )
        self._jobs: list[InflateJob] = []
        self._runs_jobs = False  # set by a transport that runs ``take_job``'s jobs (``run_jobs``)
        timeout = self._config.idle_timeout_s
        self._idle = IdleWatch(self, timeout) if timeout else None
        self._on_output = on_output
        self._on_closed = on_closed
        open_ = authenticated or self._config.authenticator is None
        self._state = State.OPEN if open_ else State.AUTHENTICATING
        self._admitted = self._state is State.OPEN  # ops were served (``authenticated``)
        self._close_request: CloseConnection | None = None  # set on entering CLOSING
        self._now = 0.0  # the latest monotonic time seen, for output without one
        self._logged: set[str] = set()  # kinds of trouble already logged (one line each)
        self._auth_nonce: str | None = None
        if self._config.auth_challenge and self._state is State.AUTHENTICATING:
            self._auth_nonce = auth_nonce
            if auth_nonce is None:
                self._auth_nonce = new_challenge()
                # before any op, whatever the status level: the client needs it to authenticate
                msg = self._auth_nonce
                self.send(Status(level="info", msg=msg, id=AUTH_CHALLENGE_ID))

    # ---- inputs -------------------------------------------------------------

    def receive_frame(self, frame: str | bytes, now: float, *, binary: bool = False) -> None:
        """Process one incoming frame: one JSON text, or one CBOR item when ``binary``.

        Args:
            frame: the frame's payload.
            now: monotonic seconds.
            binary: the frame came as binary (a WebSocket binary message, a CBOR
                item on a stream): CBOR (D21, D27).

        Never raises for anything the peer sent; see the module docstring.
        Frames arriving after the session asked to close are ignored.
        """
        if not self._state.takes_input:
            return
        self._now = now
        if self._idle is not None:
            self._idle.last_input = now
        op_name: str | None = None
        op_id: str | int | None = None
        try:
            fast = (
                None
                if binary or self._state is not State.OPEN or not _PUBLISH_DECODE
                else decode_publish(frame)
            )
            if fast is not None:  # the publish hot path: no pydantic
                op_name, op_id = "publish", fast.id
                self._dispatch(fast, now)
                return
            if binary:
                obj = decode_cbor(
                    frame.encode() if isinstance(frame, str) else frame, typed_arrays=True
                )
            else:
                obj = decode_json(frame)
            op_id = peek_id(obj)
            op = parse_object(obj)
            op_name = op.op
            if self._state is State.OPEN:
                self._dispatch(op, now)
            elif gates.authenticate(self, op):
                self._move(State.OPEN)
                self._admitted = True
        except RwtError as exc:
            self._refused(exc, op_name, op_id)
        except Exception:
            self._bug(op_name, op_id)

    def inflate_png(self, png: PendingPng, op_id: str | int | None, now: float) -> None:
        """Inflate a ``png`` op's image, then handle its text as a frame (D20).

        The inflated bytes are charged to this connection's budget
        (``png_inflate_rate``). With a transport that called ``run_jobs``, the work
        becomes a job (``take_job``) that waits for the budget and runs off the
        event loop; the transport reads no further frame of this connection
        until it is done (``finish_job``), so ops keep their order. Without one
        (a bare session), it is inflated at once.

        Raises:
            RemoteProtocolError: the PNG is corrupt (inflated at once only).
        """
        wait = self._inflate_budget.charge(png.pixel_bytes, now)
        if not self._runs_jobs:
            self.receive_frame(png.inflate(), now)
            return
        self._jobs.append(InflateJob(png, op_id, now + wait))

    def start(self, now: float) -> None:
        """The transport serves the connection from ``now``: time-driven rules count from it."""
        if self._idle is not None:
            self._idle.start(now)

    def take_job(self) -> InflateJob | None:
        """The oldest job waiting for the transport to run it (``InflateJob.run``), or None."""
        return self._jobs.pop(0) if self._jobs else None

    @property
    def has_jobs(self) -> bool:
        """Whether jobs wait: the transport runs them before the next frame."""
        return bool(self._jobs)

    def finish_job(self, job: InflateJob, result: bytes | BaseException, now: float) -> None:
        """Take a job's outcome: its text is handled as a frame, its error reported.

        Args:
            job: what ``take_job`` gave.
            result: what ``job.run()`` returned, or the exception it raised.
            now: monotonic seconds.
        """
        if not self._state.takes_input:
            return
        if isinstance(result, RwtError):
            self._refused(result, "png", job.op_id)
        elif isinstance(result, BaseException):
            try:  # a bug in the job: reported and logged with its traceback, as in a handler
                raise result
            except Exception:
                self._bug("png", job.op_id)
        else:
            self.receive_frame(result, now)

    def _bug(self, op_name: str | None, op_id: str | int | None) -> None:
        """Report an exception that is not an ``RwtError``: a bug, logged once per connection."""
        if self._log_once("bug"):
            logger.exception("bug while handling a frame from %s", self._client_id)
        else:
            logger.debug("bug while handling a frame from %s", self._client_id, exc_info=True)
        try:
            self.report(StatusLevel.ERROR, _prefixed(op_name, "internal error"), op_id)
        except Exception:  # the report is total; a bug there must still not reach the transport
            logger.debug("cannot report a bug to %s", self._client_id, exc_info=True)

    def _log_once(self, kind: str) -> bool:
        """Whether trouble of ``kind`` is new on this connection (so that one line is logged)."""
        if kind in self._logged:
            return False
        self._logged.add(kind)
        return True

    def _refused(self, exc: RwtError, op_name: str | None, op_id: str | int | None) -> None:
        text = exc.message
        authenticating = self._state is State.AUTHENTICATING
        if authenticating and "authentication" not in text:
            text = f"{gates.AUTH_REQUIRED}: {text}"
        self.report(exc.level, _prefixed(op_name, text), op_id)
        if authenticating:  # D23: a connection that does not authenticate goes
            self.request_close(CloseCode.POLICY_VIOLATION, gates.AUTH_REQUIRED)

    def _dispatch(self, op: OpModel | PublishView, now: float) -> None:
        """Check a validated op against the access rules, then run its handler.

        Raises:
            RwtError: the op was refused; the caller reports it. A denied
                ``call_service``/``send_action_goal`` is also answered (D4).
        """
        gates.check_access(self, op)
        HANDLERS[type(op)](self, op, now)

    def handle_timer(self, now: float) -> None:
        """Run whatever was due at or before ``now`` (timers from ``get_timer``)."""
        if self._state is not State.CLOSED:
            self._now = max(self._now, now)
            self._timers.run_due(now)

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
        self._graph.release(self._client_id)

    def close(self) -> None:
        """The connection is gone: release everything it held in the graph. Idempotent."""
        if self._state is State.CLOSED:
            return
        self._move(State.CLOSED)
        try:
            self._timers.clear()
            self._holdings.clear()
            self._fragments.clear()
            self._graph.release(self._client_id)
        finally:  # even if releasing raised, the owner forgets the connection
            if self._on_closed is not None:
                self._on_closed(self._client_id)

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
            self._watch.after_take()
        return frames

    def commands_to_run(self) -> list[Command]:
        """Take every command queued for the transport."""
        commands, self._commands = self._commands, []
        return commands

    def get_timer(self) -> float | None:
        """The monotonic time at which ``handle_timer`` must next be called, or None."""
        return None if self._state is State.CLOSED else self._timers.next_deadline()

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
    def config(self) -> SessionConfig:
        """This connection's settings."""
        return self._config

    @property
    def holdings(self) -> Holdings:
        """What this connection holds in the graph (subscriptions, advertisements, ...)."""
        return self._holdings

    @property
    def provider_link(self) -> ProviderLink:
        """The graph's way to this peer's services and actions."""
        return self._provider_link

    @property
    def fragments(self) -> Reassembler:
        """This connection's incomplete ``fragment`` and ``png`` messages (D19)."""
        return self._fragments

    @property
    def auth_nonce(self) -> str | None:
        """This connection's challenge (D31), sent before anything else; None without one."""
        return self._auth_nonce

    @property
    def status_level(self) -> StatusLevel:
        """The least severe status this connection receives (D2; ``set_status_level``)."""
        return self._status_level

    def set_status_level(self, level: StatusLevel) -> None:
        """Change which status frames this connection receives (``set_level``, D2)."""
        self._status_level = level

    def run_jobs(self) -> None:
        """The transport runs ``take_job``'s jobs from now on, off its event loop."""
        self._runs_jobs = True

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

    def _move(self, target: State) -> None:
        """Change ``state`` along ``lifecycle.TRANSITIONS``; LocalProtocolError otherwise."""
        self._state = advance(self._state, target)

    @property
    def dropped_frames(self) -> int:
        """Topic messages dropped so far because the peer was too slow (D24)."""
        return self._outbox.dropped

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
    def water_marks(self) -> tuple[int, int]:
        """The outbox's (high, low) watermarks in bytes, for input backpressure (docs/limits.md)."""
        return self._outbox.high_water_bytes, self._outbox.low_water_bytes

    # ---- helpers for handlers -------------------------------------------------

    def send_frames(self, frames: Sequence[OutFrame], topic: str | None = None) -> None:
        """Queue the frames of one message (its parts stay together, D24) and wake the transport.

        Past the limit, the oldest topic messages go (D24); when undroppable
        frames alone exceed the limit the peer is not reading at all, and the
        connection is closed rather than let memory grow. A topic message
        larger than the limit goes out alone or is dropped with a status naming
        ``--send-buffer-limit`` (``outbox``, ``backpressure``).

        Args:
            frames: the frames of one message, shared with other connections (never copied).
            topic: the topic of a message, as the peer spells it, for the status of a drop.
        """
        if not self._state.sends:
            return
        limit = self._outbox.limit_bytes
        if self._outbox.undroppable_bytes > limit and not all(f.droppable for f in frames):
            self.request_close(
                CloseCode.POLICY_VIOLATION,
                f"send buffer overflow: over {limit} bytes unread",
                abort=True,
            )
            return
        outbox = self._outbox
        was_empty = len(outbox) == 0
        dropped, oversized = outbox.dropped, outbox.dropped_oversized
        outbox.extend(frames)
        self._watch.after_push(dropped, oversized, self._now, frames, topic)
        if was_empty or outbox.queued_bytes > outbox.high_water_bytes:
            self._wake()  # above the high watermark too: the transport applies backpressure

    def send(
        self,
        op: OpModel,
        *,
        compression: Compression = Compression.NONE,
        fragment_size: int | None = None,
        codec: MessageCodec | None = None,
    ) -> None:
        """Queue an op that must not be dropped (responses, results, status, requests).

        Args:
            op: the op (``ServiceResponse(...)``), its values in the internal form.
            compression: the encoding the request asked for (``call_service`` and
                ``send_action_goal`` replies, spec 3.3.8/3.3.12): ``none`` (JSON),
                ``png`` (a ``png`` op, D20) or ``cbor``/``cbor-raw`` (one binary
                CBOR frame, D21).
            fragment_size: split JSON into ``fragment`` ops, and PNG data into
                ``png`` parts, above this many characters (D19).
            codec: the message type of the op's ``values`` (else ``msg``), so that
                CBOR carries its numeric arrays as typed arrays (REF §3.2).

        Never raises: an op with no wire form is replaced by its failure reply
        (a waiting caller still hears back, D4) or an error status
        (``encoding.safe_op_frames``), and one line is logged per connection.
        """
        frames, failure = safe_op_frames(
            op, compression=compression, fragment_size=fragment_size, codec=codec
        )
        if failure is not None:
            self._unencodable(failure)
        self.send_frames(frames)

    def send_request(self, op: OpModel, what: str) -> None:
        """Queue a request to this connection's peer as a provider, if it has room.

        ``op`` is a ``call_service`` (or goal) the graph forwards to the
        service this peer advertised; ``what`` names it for the error
        (``service /add``). Requests are never dropped (D24), so a request
        that would take the replies and requests waiting for this peer over
        ``send_buffer_limit`` is refused: the caller fails at once and the
        provider, which is not at fault, stays connected (docs/limits.md).

        Raises:
            GraphError: ``<what>: provider busy ...``; nothing was queued.
        """
        frames, failure = safe_op_frames(op)
        if failure is not None:
            self._unencodable(failure)
        outbox = self._outbox
        if not outbox.fits_kept(frames):
            raise GraphError(
                f"{what}: provider busy: {outbox.undroppable_bytes} bytes of requests wait "
                f"for it already and this one would take them over its send buffer limit "
                f"({outbox.limit_bytes} bytes); try again later"
            )
        self.send_frames(frames)

    def _unencodable(self, failure: EncodeFailure) -> None:
        """Log an op that had no wire form: one warning per connection, then debug lines."""
        level = logging.WARNING if self._log_once("encode") else logging.DEBUG
        logger.log(
            level,
            "event=unencodable client=%s op=%s reason=%r",
            self._client_id,
            failure.op,
            failure.reason,
        )

    def call_at(self, deadline: float, callback: Callable[[float], None]) -> Timer:
        """Run ``callback(now)`` from ``handle_timer`` once ``now >= deadline``.

        Wakes the transport so that it sees the new deadline in ``get_timer``.
        """
        timer = self._timers.schedule(deadline, callback)
        if self._state is not State.CLOSED:
            self._wake()
        return timer

    def watch_fragments(self) -> None:
        """Make sure the earliest fragment deadline has a timer (D19 expiry)."""
        deadline = self._fragments.next_deadline()
        if deadline is not None and self._fragment_timer is None:
            self._fragment_timer = self.call_at(deadline, self._expire_fragments)

    def _expire_fragments(self, now: float) -> None:
        self._fragment_timer = None
        for kind, op_id, received, total in self._fragments.expire(now):
            self.report(
                StatusLevel.ERROR,
                f"{kind}: message {op_id!r} dropped incomplete after"
                f" {self._config.fragment_timeout_s:g} s ({received} of {total} parts)",
                op_id,
            )
        self.watch_fragments()

    def report(self, level: StatusLevel, text: str, op_id: str | int | None = None) -> None:
        """Send a ``status`` frame if this connection's level admits it (spec 3.2, D1-D3)."""
        wire = level.wire
        if wire == "none" or not self._status_level.admits(level):
            return  # no status is sent at level none (``admits`` never lets it through)
        self.send(Status(level=wire, msg=text, id=op_id))

    def deliver(self, subscription: TopicSubscription, event: MessageEvent) -> None:
        """Queue one topic message for the peer, in the subscription's merged encoding.

        The frames are made once per distinct form and shared with every other
        subscriber asking for it (``encoding.safe_publish_frames``). A message
        that cannot be encoded (a bug, or a type the serializer lacks) is
        reported as an error status and skipped, logged once per connection;
        it never reaches the publisher.
        """
        self._now = max(self._now, event.now)
        params = subscription.params
        frames = safe_publish_frames(
            event, subscription.spelling, params.compression, params.fragment_size
        )
        if isinstance(frames, EncodeFailure):
            self._unencodable(frames)
            self.report(
                StatusLevel.ERROR,
                f"subscribe: cannot send a message of {subscription.spelling}"
                f" as {params.compression}",
            )
            return
        self.send_frames(frames, subscription.spelling)

    def check_cap(self, count: int, cap: int, what: str) -> None:
        """Refuse an op that would hold more than ``cap`` of ``what`` (docs/limits.md).

        Raises:
            LimitError: ``count`` (what the connection holds now) reached ``cap``.
        """
        if count >= cap:
            raise LimitError(f"{what}: this connection holds {cap} already (the server's limit)")

    def _wake(self) -> None:
        if self._on_output is not None:
            self._on_output()


def _prefixed(op_name: str | None, text: str) -> str:
    if op_name is None or text.startswith(f"{op_name}: "):
        return text
    return f"{op_name}: {text}"
