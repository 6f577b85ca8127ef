"""The interface between the protocol session and whatever graph backs it.

``rwt_protocol`` cannot import the graph (layering), so the session
talks to a ``GraphPort`` and the graph calls back into a ``TopicSink``. Both are
structural ``typing.Protocol`` types; ``rwt_graph.core.GraphCore`` implements the
port (``Graph.port``; ``Graph`` itself is the embedding API, docs/embedding.md),
and ``rwt_graph.port.GraphFront`` adds what a protocol front end needs beside
it (the change feed, the types, the nodes, the timeline). All calls are
synchronous and never block: the graph is in-memory.

The port speaks the graph's terms, not a protocol's: a topic, a type name, a
message, a service and its arguments, so that every front end (rosbridge's
handlers, the Foxglove session, a link, in-process code) calls it alike and
none builds another protocol's ops to reach it. Names passed here are as their
sender spelled them (D26); the graph resolves them.

The other way, what the graph forwards to a client's provider stays op-shaped:
``ServiceProvider.on_service_request`` takes a ``CallService``,
``ActionProvider.on_action_goal`` a ``SendActionGoal``. Those are the frames a
rosbridge provider is sent as they are, with the graph's request id and the
provider's own spelling; the graph builds each once, the rosbridge session
sends it without copying its fields again, and the links' providers read the
same few fields (``service``, ``args``, ``id``) a tuple of them would carry.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping
from enum import IntEnum
from typing import TYPE_CHECKING, NamedTuple, Protocol, TypeVar

if TYPE_CHECKING:
    from .ops import CallService, CancelActionGoal, SendActionGoal
    from .qos import QosProfile

__all__ = [
    "ActionProvider",
    "BatchSink",
    "ClientId",
    "ExpiringEvent",
    "GoalDone",
    "GoalFeedback",
    "GoalHandle",
    "GoalStatus",
    "GraphPort",
    "LossSink",
    "MessageCodec",
    "MessageEvent",
    "OfferWatch",
    "Pending",
    "PublishNote",
    "PublishNotes",
    "ServicePort",
    "ServiceProvider",
    "ServiceReply",
    "TopicSink",
]

ClientId = str
"""Opaque identity of one connection (or in-process participant) in the graph."""


class MessageCodec(Protocol):
    """What the encoders need from a message's type (the graph provides it).

    The protocol layer cannot read message types (layering), yet CBOR needs each
    numeric array's element type (REF §3.2) and cbor-raw needs the dialect's wire
    serialization (REF §3.5). ``rwt_graph`` implements this per message type.
    """

    def typed(self, msg: Mapping[str, object]) -> Mapping[str, object]:
        """Return ``msg`` with every numeric array as a numpy array of its element type.

        ``uint8[]``/``char[]`` stay ``bytes``; ``bool[]`` and ``string[]`` stay lists;
        ROS 2 ``byte[]`` becomes ``uint8``. The result is only read (CBOR encoding).
        """

    def serialize(self, msg: Mapping[str, object]) -> bytes | memoryview:
        """The dialect's wire form: CDR with its 4-byte header (ROS 2), or ROS 1 serialization.

        A large result may be a read-only byte view (no copy into ``bytes``).
        """

    def deserialize(self, data: bytes) -> dict[str, object]:
        """The message in the internal form from its wire form (the inverse of ``serialize``).

        Raises:
            ValueError: ``data`` is not a message of this type in that form.
        """


_T = TypeVar("_T")


class MessageEvent:
    """One message published on a topic, shared by every subscriber.

    Subscribers encode through ``encoded`` so that a message published to N
    subscribers is serialized once per distinct encoding ("encode once").

    Attributes:
        topic: resolved topic name (``/chatter``).
        type_name: canonical message type (``std_msgs/msg/String``).
        msg: the message in the graph's internal form (a dict; ``bytes`` for
            ``uint8[]``), never mutated after publication. An event made
            without it (a publisher that gave only ``wire``) reads it from
            ``wire`` with ``codec.deserialize`` on first use, once for every
            subscriber; if ``wire`` does not decode, every read raises that
            ``ValueError`` (each subscriber's delivery catches it: the
            subscriber skips the message and is told, ``encoding.safe_publish_frames``).
        now: monotonic seconds when it was published.
        stamp: wall-clock seconds since the epoch when it was published (the
            ``secs``/``nsecs`` of cbor-raw, REF §3.5).
        codec: the message type's encoder support, or None when the publisher
            gave none (CBOR then sends plain arrays and cbor-raw is refused).
        wire: the message in the graph dialect's wire serialization (CDR with
            its header, or ROS 1's) exactly as it arrived, when it arrived
            serialized (a link's sample, a bag's record); None when it came as
            values. Subscribers that send this form pass it on unchanged
            instead of serializing ``msg`` (Foxglove message data, cbor-raw).
            Subscribers that send it so never decode a message given only as ``wire``.
        lifespan: seconds a subscriber's queue may keep it waiting while a newer
            message of the topic waits behind it (a ROS 2 sample: docs/ros2.md,
            "Latency under rate"); 0: as long as the queue's byte bound allows.
        expires: the monotonic time (seconds) after which it is never delivered:
            ``now`` plus the lifespan of its topic's QoS (protocol 2.1.0, D63),
            ``math.inf`` without one. Only an event made by ``expiring`` has one
            of its own; every other reads the class's ``math.inf`` (no cost
            per message).
        memos: the forms ``encoded`` and ``memo`` made, by key; a hot path may
            read and fill it directly with the same care for keys (no call).
            Those keys are strings or tuples that start with one; an ``int``
            (or an ``(int, int)`` tuple) is a Foxglove subscription id's message
            data frame (``rwt_foxglove.session``).
    """

    __slots__ = (
        "_error",
        "_msg",
        "codec",
        "encodings_made",
        "lifespan",
        "memos",
        "now",
        "stamp",
        "topic",
        "type_name",
        "wire",
    )

    def __init__(
        self,
        topic: str,
        type_name: str,
        msg: dict[str, object] | None,
        now: float,
        stamp: float = 0.0,
        codec: MessageCodec | None = None,
        wire: bytes | None = None,
        lifespan: float = 0.0,
    ) -> None:
        """Raises ``ValueError`` for an event with no ``msg`` and no ``wire`` and ``codec``."""
        if msg is None and (wire is None or codec is None):
            raise ValueError("a message event needs msg, or wire and the codec that reads it")
        self.topic = topic
        self.type_name = type_name
        self._msg = msg
        self._error: str | None = None  # why ``wire`` does not decode
        self.now = now
        self.stamp = stamp
        self.codec = codec
        self.wire = wire
        self.lifespan = lifespan
        self.encodings_made = 0
        self.memos: dict[Hashable, object] = {}

    expires: float = math.inf  # (``ExpiringEvent`` has its own; the attributes' text)

    def expiring(self, expires: float) -> MessageEvent:
        """This message with ``expires`` (monotonic seconds): a copy sharing its forms (D63).

        The copy shares ``memos``, so a form made for either serves both.
        """
        event = ExpiringEvent.__new__(ExpiringEvent)
        for name in MessageEvent.__slots__:
            setattr(event, name, getattr(self, name))
        event.expires = expires
        return event

    @property
    def msg(self) -> dict[str, object]:
        """The message in the internal form, decoded from ``wire`` on first use if need be.

        Raises:
            ValueError: ``wire`` is not a message of the type (the same error each time).
        """
        msg = self._msg
        if msg is None:
            msg = self._msg = self._decode()
        return msg

    def _decode(self) -> dict[str, object]:
        if self._error is None:
            assert self.codec is not None and self.wire is not None  # (``__init__``)
            try:
                return self.codec.deserialize(self.wire)
            except ValueError as exc:
                self._error = str(exc)
        # a fresh error each time: one raised again would grow its traceback
        raise ValueError(self._error)

    def encoded(self, key: Hashable, make: Callable[[], _T]) -> _T:
        """Return the delivery form for ``key``, making it on first use.

        ``key`` names everything the form depends on (encoding, topic spelling,
        fragment size); each call of ``make`` counts in ``encodings_made``.
        """
        if key in self.memos:
            return self.memos[key]  # type: ignore[return-value]
        value = self.memos[key] = make()
        self.encodings_made += 1
        return value

    def memo(self, key: Hashable, make: Callable[[], _T]) -> _T:
        """Like ``encoded`` for an intermediate form (not counted in ``encodings_made``)."""
        if key in self.memos:
            return self.memos[key]  # type: ignore[return-value]
        value = self.memos[key] = make()
        return value


class ExpiringEvent(MessageEvent):
    """A ``MessageEvent`` with an ``expires`` of its own (``MessageEvent.expiring``)."""

    __slots__ = ("expires",)

    expires: float


class TopicSink(Protocol):
    """Receives the messages of one topic for one subscriber."""

    def on_message(self, event: MessageEvent) -> None:
        """Take one message; must not block or raise."""


class BatchSink(TopicSink, Protocol):
    """A ``TopicSink`` that also takes the messages of one turn of the loop in one call.

    A sink that only queues output for a connection (a Foxglove client's, a
    rosbridge client's with ``rosbridge-batch-sink``) has it: while a server
    serves the graph, serialized messages published on a topic whose every
    subscriber is such a sink are handed over as a batch at the end of the event
    loop's turn (docs/embedding.md, "Batched delivery"), and a link's run of
    samples in one call (``GraphCore.deliver_many``).
    """

    def on_messages(self, events: list[MessageEvent]) -> None:
        """Take ``events`` in order, as ``on_message`` would one by one; never blocks or raises."""


class LossSink(Protocol):
    """A ``TopicSink`` that can be told of messages lost before they reached this server.

    A link that learns its topic's messages were lost on the way (a gap in a remote
    publisher's sequence numbers: a full queue between the server's processes, or
    the other middleware dropped them) tells the topic's subscribers through
    ``Topic.report_lost``; each sink with ``on_lost`` tells its client in its
    protocol's words (a ``warning`` status, D61). A sink without it is not told.
    """

    def on_lost(self, count: int) -> None:
        """``count`` messages of the topic were lost before they reached this server."""


class OfferWatch(Protocol):
    """A publisher registration with a ``qos``, told of its topic's offer (D64, D65).

    ROS 2 tells a publisher what concerns its offer (``offered deadline
    missed``, ``offered incompatible QoS``); a rosbridge client that advertised
    with a ``qos`` hears of them as warning statuses (``advertise``'s ``watch``).
    """

    def on_offer(self, offered: QosProfile | None, latest: Callable[[], float]) -> None:
        """The topic's offer now: at registration, whenever it changes, None once gone.

        ``latest`` gives the monotonic time of the topic's latest message (``-inf``
        before any), for the offer's deadline (D65). None: the client no longer
        publishes with a ``qos`` there. Must not raise.
        """

    def on_incompatible(self, offered: QosProfile, reasons: list[str]) -> None:
        """A subscription asks what ``offered`` cannot meet (``reasons``, D64); must not raise.

        Once per episode: from the first such subscription until none is left,
        or the offer changes.
        """


class GoalStatus(IntEnum):
    """``action_msgs/msg/GoalStatus`` codes (spec 3.3.15, REF §6.3)."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6


ServiceReply = Callable[[bool, object], None]
"""Called once with ``(result, values)``: values is a response dict on success,
an error text on failure (D28)."""

GoalFeedback = Callable[[dict[str, object]], None]
"""Called with each feedback message of a goal."""

GoalDone = Callable[[GoalStatus, bool, object], None]
"""Called once with ``(status, result, values)`` when a goal ends (D4, D18)."""


class Pending(Protocol):
    """A call or goal in flight, as its caller holds it."""

    def forget(self) -> None:
        """Stop waiting: no reply will be delivered (timeout, caller gone)."""


class GoalHandle(Pending, Protocol):
    """A goal in flight, as its caller holds it."""

    def request_cancel(self) -> None:
        """Ask the action server to cancel the goal (spec 3.3.13)."""


class ServiceProvider(Protocol):
    """The session side of a client-advertised service (spec 3.3.6, REF §2.7)."""

    def on_service_request(self, request: CallService) -> None:
        """Forward a request as the provider gets it.

        ``request.id`` is the graph's request id (a str,
        ``service_request:<name>:<n>``), ``request.service`` is spelled as the
        provider advertised it (D26) and ``request.args`` is the request in the
        internal form (a dict).

        Raises:
            RwtError: the provider cannot take it now (busy, docs/limits.md);
                the caller fails with the reason.
        """

    def on_service_lost(self, service: str, reason: str) -> None:
        """The service was taken away from this provider (replaced, D15)."""


class ActionProvider(Protocol):
    """The session side of a client-advertised action (spec 3.3.10, REF §2.15-2.16)."""

    def on_action_goal(self, goal: SendActionGoal) -> None:
        """Forward a goal as the provider gets it.

        ``goal.id`` is the graph's goal id (a str, ``action_goal:<name>:<n>``),
        ``goal.action`` and ``goal.action_type`` are spelled as the provider
        advertised them (D26), ``goal.args`` is the goal in the internal form
        and ``goal.feedback`` is true (the graph forwards feedback to callers
        that asked for it).

        Raises:
            RwtError: the provider cannot take it now (busy, docs/limits.md);
                the caller's goal is aborted with the reason.
        """

    def on_action_cancel(self, cancel: CancelActionGoal) -> None:
        """Forward a cancel request for the goal ``cancel.id`` (a str, as ``on_action_goal``'s)."""

    def on_action_lost(self, action: str, reason: str) -> None:
        """The action was taken away from this provider (replaced, D15)."""


class PublishNote(NamedTuple):
    """What the graph's safety envelope did to a client's publish (docs/safety.md, D67).

    Attributes:
        text: what happened, for the publisher (``/cmd_vel: linear.x 2 clamped to 0.5
            (bound [-0.5, 0.5])``).
        dropped: nothing was delivered (past the topic's rate).
        first: the first of its episode: a stream's front end tells its client of
            this one only (one warning per episode), a request's of each.
    """

    text: str
    dropped: bool
    first: bool


PublishNotes = Callable[[PublishNote], None]
"""Where a publish's ``PublishNote`` goes: its front end's way of telling its client."""


class ServicePort(Protocol):
    """What a server session needs from the graph for services and actions.

    ``path`` is the JSON path of the payload (``args`` or ``values``) in the
    frame it came in, for error texts (``$.args``); ``$`` by default.
    """

    def advertise_service(
        self, client: ClientId, service: str, type_name: str, provider: ServiceProvider
    ) -> str:
        """Offer ``service`` of ``type_name`` (newest advertiser wins, D15); return its type.

        The type returned is the canonical name (``std_srvs/srv/Trigger``).
        """

    def unadvertise_service(self, client: ClientId, service: str) -> None:
        """Withdraw a service ``client`` advertised; its pending calls fail (D15)."""

    def call_service(
        self,
        client: ClientId,
        service: str,
        args: object,
        reply: ServiceReply,
        *,
        type_name: str | None = None,
        timeout_s: float | None = None,
        path: str = "$",
    ) -> Pending:
        """Call ``service`` with ``args``; ``reply`` may run before this returns.

        ``args``: an object, a list (positional, D25) or None. ``service`` is a
        name without a ``#id`` suffix (the session splits it off, D25);
        ``type_name``, when given, must be the service's type. ``timeout_s``:
        how long the caller waits for a service a link is still discovering (it
        also ends the call then, with ``Pending.forget``); None, the link's own wait.
        """

    def service_response(
        self,
        client: ClientId,
        service: str,
        request_id: str | int | None,
        result: bool,
        values: object,
        *,
        path: str = "$",
    ) -> None:
        """Answer the request ``request_id`` forwarded to ``client`` (only the advertiser may, D15).

        ``values`` is the response when ``result`` is true, else the reason its caller gets (D28).
        """

    def advertise_action(
        self, client: ClientId, action: str, type_name: str, provider: ActionProvider
    ) -> str:
        """Offer ``action`` of ``type_name`` (newest advertiser wins); return its canonical type.

        ``type_name`` stays as spelled for the goals the provider gets.
        """

    def unadvertise_action(self, client: ClientId, action: str) -> None:
        """Withdraw an action ``client`` advertised; its goals abort."""

    def send_action_goal(
        self,
        client: ClientId,
        action: str,
        args: object,
        done: GoalDone,
        feedback: GoalFeedback | None = None,
        *,
        path: str = "$",
        request_id: str | None = None,
    ) -> GoalHandle:
        """Send the goal ``args`` to ``action``; ``done`` may run before this returns.

        ``feedback``, when given, gets the goal's feedback. No action type is
        checked (clients name one action in different packages, REF §7.3).
        ``request_id``: the caller's id of the goal (the op's ``id``), by which
        any client may cancel it; it lets the goal outlive its caller (D35).
        """

    def cancel_action_goal(self, client: ClientId, action: str, request_id: str) -> None:
        """Ask to cancel the goal of ``action`` its caller named ``request_id`` (D35).

        ``client`` asks; the caller may be another connection, or gone.
        """

    def action_feedback(
        self,
        client: ClientId,
        action: str,
        goal_id: str | int | None,
        values: object,
        *,
        path: str = "$",
    ) -> None:
        """Feedback ``values`` from the advertiser of ``action`` for the goal ``goal_id``."""

    def action_result(
        self,
        client: ClientId,
        action: str,
        goal_id: str | int | None,
        result: bool,
        values: object,
        *,
        status: int | None = None,
        path: str = "$",
    ) -> None:
        """The end of the goal ``goal_id`` from the advertiser of ``action`` (D18).

        ``status``: the terminal ``GoalStatus`` code; None, SUCCEEDED when
        ``result`` is true, else ABORTED.
        """


class GraphPort(ServicePort, Protocol):
    """What a server session needs from the graph: topics (spec 3.3.1-3.3.5) and services.

    Every method raises ``rwt_protocol.errors.GraphError`` (or a subclass) for a
    request the graph refuses; the session reports it as a ``status``.
    """

    def advertise(
        self,
        client: ClientId,
        topic: str,
        type_name: str,
        *,
        latch: bool = False,
        qos: QosProfile | None = None,
        watch: OfferWatch | None = None,
    ) -> str:
        """Register ``client`` as a publisher of ``topic`` (latched when ``latch``).

        ``qos`` (protocol 2.1.0): the topic's first publisher registration with
        one fixes its offered QoS (D62). ``watch``: with ``qos``, told of the
        offer as it goes (``OfferWatch``; the latest registration's replaces the
        client's earlier one). Returns the topic's canonical type.
        """

    def offered_qos(self, topic: str) -> QosProfile | None:
        """The QoS ``topic``'s publishers offer (its first registration's, D62), or None."""

    def unadvertise(self, client: ClientId, topic: str) -> None:
        """Remove ``client`` as a publisher of ``topic``."""

    def publish(
        self,
        client: ClientId,
        topic: str,
        msg: object,
        *,
        latch: bool = False,
        path: str = "$",
        notes: PublishNotes | None = None,
    ) -> tuple[str, ...]:
        """Validate and publish ``msg`` on ``topic``; return the paths filled with defaults (D7).

        ``msg`` is decoded JSON (a dict); ``path`` is its JSON path in the op,
        for error texts (``$.msg``). A remote client's message passes the graph's
        safety envelope, if it has one (docs/safety.md): ``notes`` hears of a clamp
        or a drop; a refusal raises (a ``GraphError``).
        """

    def publish_serialized(
        self,
        client: ClientId,
        topic: str,
        data: bytes,
        *,
        encoding: str,
        notes: PublishNotes | None = None,
    ) -> None:
        """Validate and publish ``data``, a message of ``topic``'s type in the graph's wire form.

        ``encoding`` names the form (``cdr`` for a ROS 2 graph, ``ros1`` for a
        ROS 1 one). ``data`` comes from a peer, so it is validated by decoding it
        once as the topic's type (a bad one raises ``CdrError``, a
        ``RemoteProtocolError``, and reaches no subscriber); then ``data`` itself
        goes on (``MessageEvent.wire``) to every subscriber that sends that form,
        never serialized again, and the decoded values to the others.
        The safety envelope checks the decoded values as ``publish``'s (``notes``);
        a clamped message goes on as values, serialized again where needed.
        """

    def subscribe(
        self,
        client: ClientId,
        topic: str,
        type_name: str | None,
        sink: TopicSink,
        *,
        qos: QosProfile | None = None,
    ) -> str:
        """Attach ``sink`` for ``client`` to ``topic`` (replacing an earlier one).

        ``type_name``, when given, must be the topic's type (or makes the topic);
        returns the canonical type. ``qos`` (protocol 2.1.0): what the subscriber
        asks of the topic (D63-D65); a sink with ``on_qos_offered`` is told the
        topic's offer (``rwt_graph.topic_qos``).
        """

    def unsubscribe(self, client: ClientId, topic: str) -> None:
        """Detach ``client``'s sink from ``topic``."""

    def release(self, client: ClientId, *, ended: bool = True) -> None:
        """Drop everything ``client`` holds (it disconnected).

        ``ended``: its connection ended; False for the end of one request of a front
        end without connections (HTTP, a 2026-07-28 MCP request), whose commands of a
        dead-man topic stand until it falls due (docs/safety.md, D68).
        """

    def type_warning(self, type_name: str) -> str | None:
        """Why a link of the graph cannot carry ``type_name`` (what to install), or None."""
