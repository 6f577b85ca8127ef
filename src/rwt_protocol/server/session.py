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
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..auth import AUTH_CHALLENGE_ID, new_challenge
from ..codecs.cbor import decode_cbor
from ..codecs.json import decode_json, decode_publish, parse_object, peek_id
from ..errors import GraphError, RwtError
from ..framing.fragments import FragmentBudget, Reassembler
from ..levels import StatusLevel
from ..ops import OpModel, PublishView, Status
from ..ops.base import Compression
from ..runtime.commands import CloseCode, CloseConnection, Command
from ..runtime.connection import SessionBase
from ..runtime.lifecycle import State
from ..runtime.outbox import FRAME_OVERHEAD_BYTES
from ..runtime.rules import ClientRules, MiB
from ..shortcuts import enabled
from . import gates
from .compat import Compat, initial_status_level
from .encoding import EncodeFailure, publish_text_size, safe_op_frames, safe_publish_frames
from .handlers import HANDLERS
from .handlers.providers import ProviderLink
from .holdings import Holdings
from .inflate import InflateJob, TokenBucket
from .pngout import PngPublishJob, PngWaiting

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    # what the fields ``SessionConfig`` takes from ``ClientRules`` name, for its __init__
    from ..auth import Authenticator  # noqa: F401
    from ..codecs.png import PendingPng
    from ..ports import ClientId, GraphPort, MessageCodec, MessageEvent
    from ..runtime.access import AccessPolicy  # noqa: F401
    from ..runtime.jobs import Job
    from ..runtime.memory import MemoryBudget
    from ..runtime.outbox import OutFrame
    from ..runtime.timers import Timer
    from .subscriptions import TopicSubscription

__all__ = ["CloseCode", "CloseConnection", "Command", "Session", "SessionConfig", "State"]

logger = logging.getLogger("rwt.session")

_PUBLISH_DECODE = enabled("publish-decode")  # docs/shortcuts.md


@dataclass(frozen=True)
class SessionConfig(ClientRules):
    """Per-connection settings of a rosbridge client: every protocol's rules and rosbridge's.

    The rules every protocol shares (``send_buffer_limit``, ``send_timeout_s``,
    ``hold_budget_s``, ``access``, ``authenticator``, ``call_timeout_s``,
    ``max_subscriptions``, ``max_advertisements``, ``max_pending_calls``,
    ``idle_timeout_s``, ``qos_lifespan_s``) are ``ClientRules``'s (``rwt_protocol.runtime.rules``),
    taken by the same keywords; the server makes one ``SessionConfig`` and every
    front end reads the part it knows.

    Attributes:
        status_level: the level a new connection starts at (D2, ``--status-level``).
        compat: whose behaviour the connection follows where rwt and rosbridge_suite
            differ (``compat.Compat``, ``--compat``; docs/differences.md).
        auth_challenge: with an authenticator, send each connection a challenge
            first (a ``status`` with ``id`` ``auth_challenge`` and the nonce as
            ``msg``) and admit only an ``auth`` whose ``rand`` is that nonce
            (``--auth-bind-connection``, D31); the authenticator then checks a
            MAC that covers ``rand`` (``RosauthVerifier(bound=True)``).
        max_message_size: the largest message reassembled from ``fragment`` or
            ``png`` parts, and the most their pending parts may hold at once,
            bytes (D19, D24, ``--max-message-size``). A ``GraphServer`` sets
            it from its ``ServerConfig.max_message_size``, the one limit of all
            its transports.
        max_pending_fragments: messages whose parts are still arriving, at most
            (D19, ``--max-pending-fragments``).
        fragment_timeout_s: seconds without a new part after which an incomplete
            message is dropped (D19, ``--fragment-timeout``; rosbridge's 600 s).
        max_queue_length: the most messages a throttled subscription queues; a
            larger ``queue_length`` is capped with a warning (D12, D24,
            ``--max-queue-length``).
        max_ids_per_topic: ``subscribe`` or ``advertise`` ids one connection may
            hold on one topic (merged per D11).
        max_pending_goals: ``send_action_goal`` ops of one connection waiting for
            their result (``--max-pending-goals``); the next gets a failed result.
        png_inflate_rate: bytes a second of ``png`` images one connection may have
            inflated, after a burst of ``max_message_size`` (``--png-inflate-rate``;
            ``inflate.TokenBucket``): past it, its later ``png`` ops wait.
        All caps are listed with what a client sees in docs/limits.md.
    """

    status_level: StatusLevel = StatusLevel.ERROR
    compat: Compat = Compat.RWT
    auth_challenge: bool = False
    max_message_size: int = 10 * MiB
    max_pending_fragments: int = 16
    fragment_timeout_s: float = 600.0
    max_queue_length: int = 100
    max_ids_per_topic: int = 100
    max_pending_goals: int = 1000
    png_inflate_rate: int = 8 * MiB


class Session(SessionBase):
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
        memory: the server's memory budget (``--memory-budget``, D44) its outbox and
            png messages waiting are charged to; None: its own bounds alone.

    The client end is ``client.ClientSession``: the same ops, from the other end.
    """

    protocol = "rosbridge"

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
        memory: MemoryBudget | None = None,
    ) -> None:
        config = config or SessionConfig()
        self._config: SessionConfig = config  # (``SessionBase`` keeps it as ``ClientRules``)
        super().__init__(
            graph,
            client_id,
            config=config,
            on_output=on_output,
            peer=peer,
            on_closed=on_closed,
            authenticating=not authenticated and config.authenticator is not None,
            memory=memory,
        )
        self._status_level = initial_status_level(config.compat, config.status_level)
        self._holdings = Holdings()
        self._provider_link = ProviderLink(self)
        self._fragments = Reassembler(
            max_bytes=config.max_message_size,
            max_pending=config.max_pending_fragments,
            timeout_s=config.fragment_timeout_s,
            shared=fragment_budget,
        )
        self._fragment_timer: Timer | None = None
        self._png_waiting = PngWaiting()  # messages to deflate off the loop (pngout)
        self.jobs.on_taken = self._png_taken
        self._inflate_budget = TokenBucket(config.png_inflate_rate, max(config.max_message_size, 1))
        self._auth_nonce: str | None = None
        self._input_lossy = False  # the frame being handled came on the lossy channel
        self._oversize_warned: set[str] = set()  # topics told of a message too large for it
        self._reads_qos = config.compat.reads_qos  # else a ``qos`` is an unknown field (D62)
        if self._config.auth_challenge and self._state is State.AUTHENTICATING:
            self._auth_nonce = auth_nonce
            if auth_nonce is None:
                self._auth_nonce = new_challenge()
                # before any op, whatever the status level: the client needs it to authenticate
                msg = self._auth_nonce
                self.send(Status(level="info", msg=msg, id=AUTH_CHALLENGE_ID))

    # ---- inputs -------------------------------------------------------------

    def handle_frame(self, frame: str | bytes, now: float, binary: bool) -> None:
        """Process one incoming frame: one JSON text, or one CBOR item when ``binary``.

        ``receive_frame`` (``SessionBase``) calls it while the session takes input.

        Args:
            frame: the frame's payload.
            now: monotonic seconds.
            binary: the frame came as binary (a WebSocket binary message, a CBOR
                item on a stream): CBOR (D21, D27).

        Never raises for anything the peer sent; see the module docstring. A
        refusal or a bug is reported with the op's name and id (``contain``).
        """
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
            if not self._reads_qos and isinstance(obj, dict) and "qos" in obj:
                # rosbridge_suite 2.1.0 knows no qos: whatever it holds, it is not read (D62)
                obj = {key: value for key, value in obj.items() if key != "qos"}
            op = parse_object(obj)
            op_name = op.op
            if self._state is State.OPEN:
                self._dispatch(op, now)
            elif gates.authenticate(self, op):
                self._move(State.OPEN)
                self._admitted = True
        except RwtError as exc:
            self._refused(exc, op_name, op_id)
        except Exception as exc:
            self.contain(exc, op_name, op_id)

    def receive_lossy_frame(self, frame: str | bytes, now: float, *, binary: bool = False) -> None:
        """Process a frame that came on the transport's lossy channel (D36).

        As ``receive_frame``; a ``subscribe`` in it gets its messages on the lossy
        lane (``open_lossy_lane``), latest-only; everything else is answered on
        the reliable channel.
        """
        self._input_lossy = True
        try:
            self.receive_frame(frame, now, binary=binary)
        finally:
            self._input_lossy = False

    @property
    def input_lossy(self) -> bool:
        """Whether the op being handled came on the transport's lossy channel (D36)."""
        return self._input_lossy

    def inflate_png(self, png: PendingPng, op_id: str | int | None, now: float) -> None:
        """Inflate a ``png`` op's image, then handle its text as a frame (D20).

        The inflated bytes are charged to this connection's budget
        (``png_inflate_rate``). With a transport that runs the jobs
        (``jobs.transport_runs``), the work becomes a job (``jobs.take``) that waits
        for the budget and runs off the event loop; the transport reads no further
        frame of this connection until it is done (``finish_job``), so ops keep their
        order. Without one (a bare session), it is inflated at once.

        Raises:
            RemoteProtocolError: the PNG is corrupt (inflated at once only).
        """
        wait = self._inflate_budget.charge(png.pixel_bytes, now)
        if not self.jobs.transport_runs:
            self.receive_frame(png.inflate(), now)
            return
        self.add_job(InflateJob(png, op_id, now + wait))

    def job_done(self, job: Job, result: object, now: float) -> None:
        """Take a job's outcome: its text is handled as a frame, its error reported.

        ``finish_job`` (``SessionBase``) calls it and contains what it raises.

        Args:
            job: what ``jobs.take`` gave (an ``InflateJob``), or
                ``jobs.take_background`` (a ``PngPublishJob``).
            result: what ``job.run()`` returned (the inflated text, the
                ``png`` frames), or the exception it raised.
            now: monotonic seconds.
        """
        if isinstance(job, PngPublishJob):
            self._png_done(job, result)
            return
        if not isinstance(job, InflateJob):
            super().job_done(job, result, now)
            return
        if not self._state.takes_input:
            return
        if isinstance(result, RwtError):
            self._refused(result, "png", job.op_id)
        elif isinstance(result, Exception):  # a bug in the job: reported and logged
            self.contain(result, "png", job.op_id, source="job")
        elif isinstance(result, bytes | str):
            self.receive_frame(result, now)

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

    def close(self) -> None:
        """The connection is gone: release everything it held in the graph. Idempotent."""
        if self._state is not State.CLOSED:
            self._holdings.clear()
            self._fragments.clear()
            self._png_waiting.clear()
            self._png_charge(-self.stats.pending_bytes)
        super().close()

    def _png_taken(self, job: Job) -> None:
        """The transport took a background job: a ``png`` message waits no more."""
        if isinstance(job, PngPublishJob):
            before = self._png_waiting.bytes
            self._png_waiting.taken(job)
            self._png_charge(self._png_waiting.bytes - before)

    def holds_anything(self) -> bool:
        """Whether it holds something in the graph, or a message still arriving (idle rule)."""
        return (
            self._holdings.holds_anything() or self.calls.in_flight > 0 or len(self._fragments) > 0
        )

    # ---- outputs ------------------------------------------------------------

    @property
    def config(self) -> SessionConfig:
        """This connection's settings: the rules every protocol shares and rosbridge's."""
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

    # ---- helpers for handlers -------------------------------------------------

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
        outbox = self.outbox
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

    def status_frames(
        self, level: StatusLevel, text: str, op_id: str | int | None = None
    ) -> Sequence[OutFrame]:
        """A ``status`` op's frames (spec 3.2), whatever the connection's level, not queued.

        Empty at level ``none``, which has no status.
        """
        wire = level.wire
        if wire == "none":
            return ()
        frames, _ = safe_op_frames(Status(level=wire, msg=text, id=op_id))
        return frames

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
        lossy = subscription.lossy and self._lossy is not None
        if params.compression is Compression.PNG and self.jobs.transport_runs:
            self._deflate_later(subscription, event, None if lossy else params.fragment_size)
            return
        frames = safe_publish_frames(
            event,
            subscription.spelling,
            params.compression,
            None if lossy else params.fragment_size,  # no fragments on the lossy lane
        )
        if isinstance(frames, EncodeFailure):
            self._encode_failed(subscription, frames, params.compression)
        elif lossy:
            self._queue_lossy(subscription, frames)
        else:
            self.send_frames(frames, subscription.spelling, event.lifespan)

    def deliver_ruled(self, subscription: TopicSubscription, event: MessageEvent) -> None:
        """``deliver`` for a subscription with QoS (``TopicSubscription.rule``, D63, D64).

        The message goes to the outbox with the subscription's rule and the end
        of its lifespan, the earlier of its topic's and the subscription's; it is
        never sent after that. A subscription without QoS takes ``deliver``, so
        the plain path pays nothing for it.
        """
        self._now = max(self._now, event.now)
        params = subscription.params
        lossy = subscription.lossy and self._lossy is not None
        if params.compression is Compression.PNG and self.jobs.transport_runs:
            self._deflate_later(subscription, event, None if lossy else params.fragment_size)
            return
        frames = safe_publish_frames(
            event,
            subscription.spelling,
            params.compression,
            None if lossy else params.fragment_size,
        )
        expires = self.message_end(event, subscription.lifespan_s)
        if isinstance(frames, EncodeFailure):
            self._encode_failed(subscription, frames, params.compression)
        elif lossy:
            self._queue_lossy(subscription, frames, expires)
        else:
            rule = subscription.rule
            self.send_frames(frames, subscription.spelling, event.lifespan, rule, expires)

    def warn_subscription(self, subscription: TopicSubscription, text: str) -> None:
        """Warn the peer of a QoS event of ``subscription`` (D64, D65), with its latest id.

        A warning status: the peer's level decides whether it hears it (D2).
        """
        op_id = next(reversed(subscription.requests), None) if subscription.requests else None
        self.report(StatusLevel.WARNING, f"subscribe: {text}", op_id)

    def deliver_many(self, subscription: TopicSubscription, events: Sequence[MessageEvent]) -> None:
        """``deliver`` each of ``events`` (a run of one topic's messages), in order.

        The messages that are one frame (not fragmented) are queued as one run
        (``SessionBase.queue_run``) and the transport is woken once for it, so a
        burst to many subscribers costs each little more than its frame
        (``rosbridge-batch-sink``, ``rwt_protocol.shortcuts``).
        Everything else goes as ``deliver`` sends it: PNG, the lossy lane,
        fragments, a message that cannot be encoded.
        """
        params = subscription.params
        compression = params.compression
        if (compression is Compression.PNG and self.jobs.transport_runs) or (
            subscription.lossy and self._lossy is not None
        ):
            for event in events:
                self.deliver(subscription, event)
            return
        if not self._sends:
            return
        spelling, size = subscription.spelling, params.fragment_size
        run: list[OutFrame] = []  # one-frame messages of one lifespan and time, queued at once
        run_now = run_lifespan = 0.0
        for event in events:
            frames = safe_publish_frames(event, spelling, compression, size)
            if isinstance(frames, EncodeFailure):
                self._encode_failed(subscription, frames, compression)
                continue
            lifespan = event.lifespan
            if run and (lifespan != run_lifespan or (lifespan > 0 and event.now != run_now)):
                self.queue_run(run, spelling, run_now, run_lifespan)
                run = []
            if len(frames) > 1 or not frames[0].droppable:  # fragments: as ``deliver`` sends them
                if run:
                    self.queue_run(run, spelling, run_now, run_lifespan)
                    run = []
                self._now = max(self._now, event.now)
                self.send_frames(frames, spelling, lifespan)
                continue
            run.append(frames[0])
            run_now = event.now if event.now > run_now else run_now
            run_lifespan = lifespan
        self.queue_run(run, spelling, run_now, run_lifespan)

    def _queue_lossy(
        self,
        subscription: TopicSubscription,
        frames: Sequence[OutFrame],
        expires: float = math.inf,
    ) -> None:
        """Queue a topic message on the lossy lane, latest-only (D36); tell of one too large.

        The warning is sent once per topic (a peer's subscriptions bound the topics).
        ``expires``: the end of its lifespan (D63), after which it is not sent.
        """
        lane = self._lossy
        if lane is None:  # the lossy channel closed: the reliable one carries it
            rule = subscription.rule
            self.send_frames(frames, subscription.spelling, 0.0, rule, expires)
            return
        # one frame: the lane's messages are made without fragment_size (no parts)
        size = sum(len(frame.data) for frame in frames)
        if len(frames) == 1 and lane.put(subscription.topic, frames[0], expires):
            return
        if len(frames) > 1:
            lane.refused += 1  # (``put`` counts the one-frame refusals)
        if subscription.topic not in self._oversize_warned and len(self._oversize_warned) < (
            self._config.max_subscriptions
        ):
            self._oversize_warned.add(subscription.topic)
            self.report(
                StatusLevel.WARNING,
                f"subscribe: a message of {subscription.spelling} ({size} bytes) is over the "
                f"lossy channel's limit ({lane.max_message_bytes} bytes, the peer's "
                "max-message-size) and was dropped; subscribe on the reliable channel for it",
            )

    def _deflate_later(
        self, subscription: TopicSubscription, event: MessageEvent, fragment_size: int | None
    ) -> None:
        """Leave a png message to a background job (pngout), in order, bounded as the outbox.

        It waits charged with its JSON text's size: past ``--send-buffer-limit``
        (the outbox and the waiting messages together) the oldest topic messages
        go (D24); past the high watermark the transport holds the publisher
        (input backpressure); while the server's memory budget is full, a
        connection past its part loses its oldest too (D44).
        """
        spelling = subscription.spelling
        cost = publish_text_size(event, spelling) + FRAME_OVERHEAD_BYTES
        job = PngPublishJob(subscription, event, fragment_size, cost)
        self._png_waiting.add(job)
        self._png_charge(cost)
        self.add_job(job, background=True)
        self._bound_waiting(spelling)
        memory = self._memory
        if memory is not None:
            excess = memory.excess(self.outbox.limit_bytes)
            if excess:
                self.make_room(excess, self._now)
        if self.stats.fill_bytes > self.wake_above_bytes:
            self._wake()  # the transport holds the publisher (input backpressure)
        self.sweep_memory()

    def _bound_waiting(self, topic: str) -> None:
        """Keep the outbox and the png messages waiting within ``--send-buffer-limit`` (D24)."""
        outbox = self.outbox
        limit = outbox.limit_bytes
        if outbox.queued_bytes + self.stats.pending_bytes > limit:
            self.shed(limit, topic)

    def shed_topic_messages(self, cap: int) -> None:
        """Drop the oldest topic messages, queued then waiting for png, down to ``cap`` bytes.

        The newest waiting message stays: as in the outbox, a message is never
        dropped for being the only one.
        """
        outbox, waiting = self.outbox, self._png_waiting
        outbox.shed_to(max(0, cap - waiting.bytes))
        while len(waiting) > 1 and outbox.queued_bytes + waiting.bytes > cap:
            job = waiting.oldest()
            self._png_charge(-job.cost)
            self.drop_background_job(job)

    def _png_charge(self, delta: int) -> None:
        """``delta`` bytes more (or fewer) wait for png: in the fill and the memory budget."""
        self.stats.pending_bytes += delta
        if self._memory is not None and delta:
            self._memory.charge(delta)

    def _png_done(self, job: PngPublishJob, result: object) -> None:
        """A deflated message is back: sent unless its subscription went meanwhile."""
        subscription = job.subscription
        if not self._state.sends or not subscription.requests:
            return
        if isinstance(result, Exception):  # a bug in the encoder: reported and logged
            self.contain(result, "subscribe", source="job")
            return
        if isinstance(result, EncodeFailure):
            self._encode_failed(subscription, result, Compression.PNG)
            return
        event, rule = job.event, subscription.rule
        expires = self.message_end(event, subscription.lifespan_s)
        if subscription.lossy:
            self._queue_lossy(subscription, result, expires)  # type: ignore[arg-type]
        else:
            self.send_frames(result, subscription.spelling, 0.0, rule, expires)  # type: ignore[arg-type]
            if self.stats.pending_bytes:  # its png op may be larger than what it was charged
                self._bound_waiting(subscription.spelling)

    def _encode_failed(
        self, subscription: TopicSubscription, failure: EncodeFailure, compression: str
    ) -> None:
        self._unencodable(failure)
        self.report(
            StatusLevel.ERROR,
            f"subscribe: cannot send a message of {subscription.spelling} as {compression}",
        )


def _prefixed(op_name: str | None, text: str) -> str:
    if op_name is None or text.startswith(f"{op_name}: "):
        return text
    return f"{op_name}: {text}"
