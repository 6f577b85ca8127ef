"""The graph's core: its state and the port that sessions and links drive.

``GraphCore`` holds the topics, services, actions and nodes of one server and
implements ``rwt_protocol.ports.GraphPort``: a session (and a link's remote
participant) advertises, subscribes, publishes and calls on behalf of a client id.
``rwt_graph.graph.Graph`` is the embedding API over it (``create_publisher`` and
friends) and hands it out as ``Graph.port``; the handles of ``rwt_graph.local``
call it directly, so a message takes the same path whichever face published it.

Its two collaborators are given, never assigned from outside: the clock at
construction (``use_clock`` swaps it for a while, e.g. a bag's time during
playback) and, while a server runs (``serving``), the spawner of async
in-process handlers and the loop's ``call_soon`` that batched delivery uses.

Batched delivery (``deliver_wire``, docs/embedding.md): while a server serves
the graph, serialized messages published on topics whose every subscriber
only queues output for a connection (``BatchSink``, a Foxglove client) are
gathered during the loop's turn and delivered at its end, each topic's run in
one call per sink, so a burst costs a call per run, not per message and sink.
Every other delivery, and every change of subscribers or publishers, delivers
the batch first, so every sink sees the graph's messages in publish order.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
from functools import partial
from typing import TYPE_CHECKING, TypeVar

from rwt_protocol.errors import GraphError
from rwt_protocol.names import resolve_name
from rwt_protocol.ports import (
    ActionProvider,
    ClientId,
    GoalDone,
    GoalFeedback,
    GoalHandle,
    MessageEvent,
    OfferWatch,
    Pending,
    PublishNotes,
    ServiceProvider,
    ServiceReply,
    TopicSink,
)
from rwt_protocol.shortcuts import enabled

from .action_status import GOAL_STATUS_ARRAY, StatusBoard, status_topic
from .actions import (
    CANCEL_GOAL_TYPE,
    ActionEntry,
    Actions,
    cancel_goals_handler,
    cancel_service_name,
)
from .calls import LOCAL_PREFIX, Soon, Spawner, guarded, is_local
from .clock import Clock, SystemClock
from .feed import ChangeFeed, EntityKind
from .link import OPEN_GATE, OPEN_OUTFLOW, InflowGate, OutflowGate
from .nodes import Nodes
from .ratelog import EpisodeLog
from .services import ServiceEntry, Services
from .topic_qos import STORE_MAX_BYTES, StoreBudget, TopicQos
from .topics import Tap, Topic
from .types import Dialect, MessageType, TypeRegistry, codec_for
from .types.wire import wire_encoding

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence

    from rwt_protocol.qos import QosProfile

    from .calls import Offer
    from .playback import Playback
    from .safety.envelope import Envelope


__all__ = ["GraphCore"]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

Message = dict[str, object]
_T = TypeVar("_T")

PUBLISHER, SUBSCRIPTION = EntityKind.PUBLISHER, EntityKind.SUBSCRIPTION

BATCH_MAX_MESSAGES = 1024
"""Messages of a turn's batch (``deliver_wire``) beyond which it is delivered at once
(docs/limits.md): a publisher that never yields holds no more than this in the graph,
and each client's queue keeps its own bounds as before."""

BATCH_MAX_BYTES = 1024 * 1024
"""Bytes of serialized messages in a turn's batch beyond which it is delivered at once."""

SOLO_AFTER_ONE = 16
"""Serialized publishes delivered at once after a turn's batch held only one message.

A publisher that yields after every message would otherwise pay a loop callback
per message for batches of one; it so pays one per ``SOLO_AFTER_ONE + 1`` messages,
and a burst is batched again from its next turn on."""


class GraphCore:
    """Topics, services, actions and nodes of one server; the ``GraphPort`` of its sessions.

    Args:
        registry: the message types; a ROS 2 registry by default.
        clock: time source; the system clock by default.

    Attributes:
        registry: the message types.
        topics: topic entries by resolved name.
        services, actions: the provider tables.
        nodes: the node of each participant.
        feed: every entity a participant gains or loses, announced once
            (``feed.ChangeFeed``): what protocols and links follow instead of
            rescanning ``topics`` and ``services``.
        taps: functions that see every published message (``topics.Tap``).
        type_checks: functions of links telling why they cannot carry a type
            (``type_warning``); a link adds one while it runs.
        inflow: the backpressure links' deliveries follow (``link.InflowGate``);
            the server serving the graph installs its own, else ``OPEN_GATE``.
        outflow: the backpressure local publishers follow when a link's queue
            for the other middleware is congested (``link.OutflowGate``); the
            server installs its own, else ``OPEN_OUTFLOW``.
        envelope: the safety envelope every remote client's publish passes
            (``safety.envelope.Envelope.install``), or None (docs/safety.md).
        max_store_bytes: the bytes a topic's transient-local store keeps at most
            (``topic_qos``, D63); the server sets its ``--send-buffer-limit``.
        stores: the bytes all topics' stores keep together, and their bound
            (``topic_qos.StoreBudget``); the server sets its ``--memory-budget``.
    """

    def __init__(self, registry: TypeRegistry | None = None, *, clock: Clock | None = None) -> None:
        self.registry = registry or TypeRegistry(Dialect.ROS2)
        self._clock: Clock = clock or SystemClock()
        self._clocks: list[Clock] = [self._clock]  # the given clock, then each use_clock's
        # each use_timeline's timeline and playback, latest last
        self._timelines: list[tuple[Callable[[], int | None], Playback | None]] = []
        # (spawner, soon) of each server serving this graph, latest last
        self._serving: list[tuple[Spawner, Soon | None]] = []
        self._soon: Soon | None = None  # the latest server's: None, no batched delivery
        self._batching = enabled("batched-delivery")
        self._batch: list[tuple[Topic, ClientId, bytes]] | None = None  # this turn's
        self._batch_bytes = 0  # of ``_batch``'s messages
        self._solo = 0  # serialized publishes still delivered at once (``SOLO_AFTER_ONE``)
        self.topics: dict[str, Topic] = {}
        self.services = Services(self.registry, self._clock, lambda: self.spawner)
        self.actions = Actions(self.registry, self._clock, lambda: self.spawner)
        self.nodes = Nodes()
        self.feed = ChangeFeed(self.nodes.node_of, self.nodes.role_of)
        self.nodes.on_change = self.feed.renode
        self.services.on_change = partial(self._offer_changed, EntityKind.SERVICE)
        self.actions.on_change = partial(self._offer_changed, EntityKind.ACTION)
        self._local_ids = itertools.count(1)
        self._reserved_topics: set[str] = set()
        self._reserved_prefixes: tuple[str, ...] = ()
        self.taps: list[Tap] = []
        self.type_checks: list[Callable[[str], str | None]] = []
        self.inflow: InflowGate = OPEN_GATE
        self.outflow: OutflowGate = OPEN_OUTFLOW
        self.envelope: Envelope | None = None
        self.max_store_bytes = STORE_MAX_BYTES
        self.stores = StoreBudget()
        # client -> the topics it publishes or subscribes to, so that its release
        # costs what it holds, not the size of the graph (a peer's thousands of
        # entities leave one by one: docs/limits.md, "Zenoh peers")
        self._held: dict[ClientId, set[str]] = {}

    # ---- collaborators ------------------------------------------------------------

    @property
    def clock(self) -> Clock:
        """The time source in use: the one given, or the latest ``use_clock``'s."""
        return self._clock

    @property
    def spawner(self) -> Spawner | None:
        """The spawner of the server serving this graph (the latest one), or None."""
        return self._serving[-1][0] if self._serving else None

    @contextlib.contextmanager
    def serving(self, spawner: Spawner, soon: Soon | None = None) -> Iterator[None]:
        """Run async in-process handlers through ``spawner`` inside the ``with`` block.

        The server enters it while it serves (``calls.Spawner``: it runs jobs in
        its event loop). Blocks may overlap (two servers of one graph): the
        latest still open is used, and leaving one in any order restores the
        others'. Outside every block an async handler fails its caller
        (``calls.require_spawner``).

        ``soon``: the loop's ``call_soon`` (``calls.Soon``), which turns batched
        delivery on inside the block (``deliver_wire``; not with the
        ``batched-delivery`` shortcut off). A batch still open when a block is
        left is delivered then.
        """
        lent = (spawner, soon if self._batching else None)
        self._serving.append(lent)
        self._soon = lent[1]
        try:
            yield
        finally:
            self.flush()
            _drop_last(self._serving, lent)
            self._soon = self._serving[-1][1] if self._serving else None

    @contextlib.contextmanager
    def use_clock(self, clock: Clock) -> Iterator[None]:
        """Make ``clock`` the graph's time inside the ``with`` block.

        Everything the graph stamps reads it (default header stamps of topics,
        service requests and goals; ``Graph.clock``, which rosapi's ``get_time``
        answers), as ``use_sim_time`` does in ROS: the bag player uses it for
        bag time (docs/record-replay.md). Readers that took the clock before
        (an authenticator) keep theirs. Blocks may overlap; the latest still
        open wins and leaving one in any order restores the others'.
        """
        self._clocks.append(clock)
        self._set_clock(clock)
        try:
            yield
        finally:
            _drop_last(self._clocks, clock)
            self._set_clock(self._clocks[-1])

    @property
    def timeline(self) -> Callable[[], int | None] | None:
        """The playback's time while a bag plays into the graph, else None.

        A call returns nanoseconds since the epoch on the bag's clock: the
        record time of the message being published while one is, else the
        playback position (it stands still while paused and steps on a seek).
        With sim time (``simtime.follow_clock``) it is the latest ``/clock``,
        None before the first. Foxglove clients get it as server time
        (docs/foxglove.md).
        """
        return self._timelines[-1][0] if self._timelines else None

    @property
    def playback(self) -> Playback | None:
        """The player whose clock is the ``timeline`` now, else None (``playback.Playback``).

        Foxglove clients drive it from their playback bar (docs/foxglove.md).
        """
        return self._timelines[-1][1] if self._timelines else None

    @contextlib.contextmanager
    def use_timeline(
        self, timeline: Callable[[], int | None], *, playback: Playback | None = None
    ) -> Iterator[None]:
        """Make ``timeline`` the graph's ``timeline`` inside the ``with`` block.

        Args:
            timeline: the time source (ns since the epoch, or None when it has none).
            playback: the player that moves ``timeline``, offered as ``playback``
                for as long; None: the timeline cannot be driven (sim time).

        Blocks may overlap; the latest still open wins and leaving one in any
        order restores the others'.
        """
        entry = (timeline, playback)
        self._timelines.append(entry)
        try:
            yield
        finally:
            _drop_last(self._timelines, entry)

    def _set_clock(self, clock: Clock) -> None:
        self._clock = self.services.clock = self.actions.clock = clock

    # ---- GraphPort ------------------------------------------------------------

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
        """Register ``client`` as a publisher of ``topic`` (spec 3.3.1); ``latch`` latches (D13).

        A publisher that latches stays latched until it goes. ``qos`` (protocol
        2.1.0): the first publisher that gives one fixes the topic's offered QoS
        while such a publisher remains (``topic_qos``, D62); ``latch`` is then
        read no more than the reference reads it (not at all for the offer).
        ``watch``: with ``qos``, told of the offer as it goes (D64, D65).

        Returns:
            The canonical type name.

        Raises:
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
            GraphError: the topic exists with another type, or is reserved.
        """
        msgtype = self.registry.message(type_name)
        name = resolve_name(topic)
        self._check_reserved(client, name)
        entry = self._topic(name, msgtype)
        self.nodes.name_of(client)
        latched = entry.publishers[client] = latch or entry.publishers.get(client, False)
        self._hold(client, entry.name)
        if qos is not None:
            self.flush()  # a batch goes before the topic's messages go one by one
            self.topic_qos(entry).add_publisher(client, qos, watch)
        self.feed.put(PUBLISHER, entry.name, client, entry.msgtype.name, latched=latched)
        return entry.msgtype.name

    def topic_qos(self, entry: Topic) -> TopicQos:
        """The QoS state of ``entry``, made (and made its ``fan_out``) on first use (D62)."""
        state = entry.qos
        if state is None:
            state = entry.qos = TopicQos(
                entry, self._clock.monotonic, self.max_store_bytes, self.stores
            )
            # the instance's own (``Topic.qos``); an attribute, not ``vars(entry)``, which
            # would make the instance's dict a real one and its reads slower
            object.__setattr__(entry, "fan_out", state.fan_out)
            entry.changed()
        return state

    def offered_qos(self, topic: str) -> QosProfile | None:
        """The QoS offered on ``topic`` (its first publisher registration's, D62), or None."""
        entry = self.topics.get(resolve_name(topic))
        return None if entry is None or entry.qos is None else entry.qos.offered

    def _settle_qos(self, entry: Topic) -> None:
        """Drop ``entry``'s QoS state once nothing in it is in force (no offer, no request)."""
        state = entry.qos
        if state is not None and state.idle:
            entry.qos = None
            object.__delattr__(entry, "fan_out")
            entry.changed()

    def unadvertise(self, client: ClientId, topic: str) -> None:
        """Remove ``client`` as a publisher; the topic goes when nobody uses it."""
        self.flush()
        entry = self.topics.get(resolve_name(topic))
        if entry is not None:
            entry.remove_publisher(client)
            self._settle_qos(entry)
            self._unhold(client, entry)
            self._collect(entry)
            self.feed.drop(PUBLISHER, entry.name, client)

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
        """Validate ``msg`` against the type of ``topic`` and deliver it (spec 3.3.3).

        Publishing without advertising is allowed once the topic's type is known
        (REF §2.3); the client then counts as a publisher until it leaves. A
        remote client's message passes the safety envelope first, if there is one
        (``envelope``, docs/safety.md): clamped, dropped (``notes`` hears of both)
        or refused.

        Args:
            client: the publishing participant.
            topic: the topic in any spelling.
            msg: the message as decoded JSON (a dict).
            latch: keep the message for later subscribers (D13).
            path: JSON path of ``msg``, for error texts.
            notes: where the envelope's clamps and drops are told (None: nowhere).

        Returns:
            Paths of the fields that were filled with defaults (D7).

        Raises:
            GraphError: the topic's type is unknown; ``EnvelopeError`` (a
                ``GraphError``): the envelope refused the message.
            FieldError: ``msg`` does not fit the type (D9).
        """
        entry, converted, missing = self.convert_publish(topic, msg, path=path)
        envelope = self.envelope
        if envelope is not None and not is_local(client):  # the one hook (safety.envelope)
            admitted = envelope.admit(client, entry, converted, notes)
            if admitted is None:
                return missing
            converted = admitted
        latched = entry.publishers.get(client)
        if latched is None:  # the first publish of this client: check it once
            self._join(client, entry)
            latched = False
        self.deliver(entry, converted, latched or latch, client)
        return missing

    def publish_serialized(
        self,
        client: ClientId,
        topic: str,
        data: bytes,
        *,
        encoding: str,
        notes: PublishNotes | None = None,
    ) -> None:
        """Publish ``data``, a message in the graph's wire form, as it is (spec 3.3.3).

        ``data`` is CDR with its encapsulation header on a ROS 2 graph
        (``encoding`` ``cdr``), the ROS 1 format on a ROS 1 one (``ros1``), as a
        Foxglove client sends its message data. It is validated by decoding it
        once as the topic's type (``WireCodec.deserialize``: the header, every
        field, no more trailing bytes than alignment explains), so a peer's bad
        bytes fail its publish and never reach a subscriber. Then ``data``
        itself goes to every subscriber that sends that form
        (``MessageEvent.wire``: Foxglove clients, cbor-raw, the links), never
        serialized again, and the values decoded to the others (JSON, CBOR,
        Python callbacks), never decoded again. Publishing without advertising
        is allowed as for ``publish``, and the safety envelope checks the values
        as it does there (``notes``); a message it clamps goes on as values.

        Raises:
            GraphError: the topic's type is unknown, or ``encoding`` is not the graph's;
                ``EnvelopeError``: the envelope refused the message.
            CdrError: ``data`` is not a message of the topic's type in that form.
        """
        entry = self.topics.get(topic)
        if entry is None:
            entry = self.topics.get(resolve_name(topic))
            if entry is None:
                raise GraphError(f"{topic} has no type yet (advertise it first)")
        expected = wire_encoding(self.registry.dialect)
        if encoding != expected:
            raise GraphError(f"encoding {encoding[:40]!r} is not this graph's ({expected})")
        codec = entry.codec
        if codec is None:
            codec = entry.codec = codec_for(self.registry, entry.msgtype)
        msg = codec.deserialize(data)
        wire: bytes | None = data
        envelope = self.envelope
        if envelope is not None and not is_local(client):  # the one hook (safety.envelope)
            admitted = envelope.admit(client, entry, msg, notes)
            if admitted is None:
                return
            if admitted is not msg:  # clamped: the client's bytes are not the message now
                msg, wire = admitted, None
        latched = entry.publishers.get(client)
        if latched is None:
            self._join(client, entry)
            latched = False
        self.deliver(entry, msg, latched, client, wire)

    def _join(self, client: ClientId, entry: Topic) -> None:
        """Make ``client`` a publisher of ``entry`` at its first publish (REF §2.3)."""
        self._check_reserved(client, entry.name)
        self.nodes.name_of(client)
        entry.publishers[client] = False
        self._hold(client, entry.name)
        self.feed.put(PUBLISHER, entry.name, client, entry.msgtype.name)

    def convert_publish(
        self, topic: str, msg: object, *, path: str = "$"
    ) -> tuple[Topic, Message, tuple[str, ...]]:
        """Find ``topic`` and convert ``msg`` to its type: the check half of ``publish``.

        Returns:
            The topic's entry, the message in the internal form and the paths
            of the fields filled with defaults (D7).

        Raises:
            GraphError: the topic's type is unknown.
            FieldError: ``msg`` does not fit the type (D9).
        """
        # Names are kept resolved, so a name found as given needs no resolving.
        entry = self.topics.get(topic)
        if entry is None:
            entry = self.topics.get(resolve_name(topic))
            if entry is None:
                raise GraphError(f"{topic} has no type yet (advertise it first)")
        msgtype = entry.msgtype
        converted = msgtype.fast(msg)  # complete and well-typed: no clock, no context
        if converted is not None:
            return entry, converted, ()
        result = msgtype.from_json(msg, path=path, now=self._clock.wall())
        return entry, result.msg, result.missing

    def subscribe(
        self,
        client: ClientId,
        topic: str,
        type_name: str | None,
        sink: TopicSink,
        *,
        qos: QosProfile | None = None,
    ) -> str:
        """Attach ``sink`` as ``client``'s subscriber of ``topic`` (spec 3.3.4).

        A new subscriber receives the latched message, if any, at once (D13).
        ``qos`` (protocol 2.1.0): what it asks of the topic (``topic_qos``): with a
        transient-local offer it gets the kept messages first unless it asks for
        volatile (D63); one incompatible with the offer receives nothing while
        the offer stands (D64). A subscriber of a topic with QoS is told the offer
        (``on_qos_offered``) either way.

        Returns:
            The canonical type name.

        Raises:
            GraphError: no type given and the topic is unknown, or a conflicting type.
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
        """
        name = resolve_name(topic)
        if type_name is None:
            entry = self.topics.get(name)
            if entry is None:
                raise GraphError(f"cannot infer the type of {topic}: give a type")
        else:
            entry = self._topic(name, self.registry.message(type_name))
        self.flush()  # the batch goes to the subscribers it was published to
        self.nodes.name_of(client)
        is_new = entry.add_subscriber(client, sink)
        self._hold(client, entry.name)
        state = entry.qos if qos is None else self.topic_qos(entry)
        if state is not None:  # (before the feed: a link reads the request with the change)
            state.add_subscriber(client, qos, sink)
        self.feed.put(SUBSCRIPTION, entry.name, client, entry.msgtype.name)
        latched = entry.latched
        if state is not None:
            if is_new and not state.replay(client, sink):
                latched = None  # volatile, or left out (D63, D64)
            elif latched is not None and any(kept is latched for kept in state.store):
                latched = None  # replayed already
            self._settle_qos(entry)
        if is_new and latched is not None:
            sink.on_message(latched)
        return entry.msgtype.name

    def unsubscribe(self, client: ClientId, topic: str) -> None:
        """Detach ``client`` from ``topic``."""
        self.flush()
        entry = self.topics.get(resolve_name(topic))
        if entry is not None:
            entry.remove_subscriber(client)
            self._settle_qos(entry)
            self._unhold(client, entry)
            self._collect(entry)
            self.feed.drop(SUBSCRIPTION, entry.name, client)

    def release(self, client: ClientId, *, ended: bool = True) -> None:
        """Drop every registration of ``client`` (it disconnected).

        Its services and actions go, failing their pending callers (D15); its own
        calls and goals are forgotten. Each step runs even if an earlier one
        failed (logged as a bug), so nothing of the client stays registered.
        Its cost is proportional to what ``client`` holds, not to the graph's size.
        ``ended``: its connection ended (the safety envelope's dead-man stops a
        topic it alone commanded, at once); False for the end of one request of a
        front end without connections (``GraphPort.release``).
        """
        self.flush()
        envelope = self.envelope
        if envelope is not None:
            guarded(
                f"the envelope's release of {client}", partial(envelope.gone, client, ended=ended)
            )
        for name in sorted(self._held.pop(client, ())):
            entry = self.topics.get(name)
            if entry is not None:
                guarded(f"releasing {client} from {name}", partial(self._drop, entry, client))
        guarded(f"releasing the services of {client}", lambda: self.services.release(client))
        guarded(f"releasing the actions of {client}", lambda: self.actions.release(client))
        guarded(f"forgetting the node of {client}", lambda: self.nodes.forget(client))

    def type_warning(self, type_name: str) -> str | None:
        """Why a link cannot carry ``type_name`` (the package to install), or None.

        The session reports it as a warning status after an advertise or a
        subscribe that succeeded here: the graph has the type, the other
        middleware cannot carry it (docs/ros2.md).
        """
        for check in self.type_checks:
            warning = check(type_name)
            if warning:
                return warning
        return None

    def _drop(self, entry: Topic, client: ClientId) -> None:
        entry.remove_publisher(client)
        entry.remove_subscriber(client)
        self._settle_qos(entry)
        self._collect(entry)
        self.feed.drop(PUBLISHER, entry.name, client)
        self.feed.drop(SUBSCRIPTION, entry.name, client)

    def _hold(self, client: ClientId, name: str) -> None:
        held = self._held.get(client)
        if held is None:
            held = self._held[client] = set()
        held.add(name)

    def _unhold(self, client: ClientId, entry: Topic) -> None:
        """Forget that ``client`` holds ``entry`` once it neither publishes nor subscribes."""
        if client in entry.publishers or client in entry.subscribers:
            return
        held = self._held.get(client)
        if held is not None:
            held.discard(entry.name)
            if not held:
                del self._held[client]

    def fail_pending(self, reason: str) -> None:
        """Answer every pending service call and goal with a failure (D4; server shutdown)."""
        for service in list(self.services.entries.values()):
            service.end_all(reason)
        for action in list(self.actions.entries.values()):
            action.end_all(reason)

    def latched(self, topic: str) -> MessageEvent | None:
        """The latched message of ``topic`` (D13), None if it has none or the topic is unknown."""
        entry = self.topics.get(resolve_name(topic))
        return None if entry is None else entry.latched

    def _offer_changed(self, kind: EntityKind, entry: Offer, added: bool) -> None:
        """A service or action table gained or lost ``entry``: tell the feed."""
        if added:
            self.feed.put(kind, entry.name, entry.owner, entry.type_name)
        else:
            self.feed.drop(kind, entry.name, entry.owner)

    # ---- ServicePort: services and actions of clients ---------------------------

    def advertise_service(
        self, client: ClientId, service: str, type_name: str, provider: ServiceProvider
    ) -> str:
        """Offer ``service`` of ``type_name``, provided by a client session (spec 3.3.6, D15).

        Raises:
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
        """
        srvtype = self.registry.service(type_name)
        entry = ServiceEntry(resolve_name(service), service, srvtype, client, provider=provider)
        self.nodes.name_of(client)
        self.services.advertise(entry)
        return srvtype.name

    def unadvertise_service(self, client: ClientId, service: str) -> None:
        """Withdraw ``service``; its pending calls fail (spec 3.3.7, D15).

        Raises:
            GraphError: ``client`` does not provide it.
        """
        self.services.unadvertise(client, service)

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
        """Call ``service`` with ``args``; ``reply(result, values)`` runs once (spec 3.3.8).

        A call that cannot run is answered too (``result: false``, D4).

        ``args`` is an object, a list (positional, D25) or None; ``type_name``,
        when given, must name the service's type; ``timeout_s`` is how long the
        caller waits for a service a link may still discover (``Services.call``).
        For an in-process service with a sync handler, ``reply`` runs before
        this returns.

        Raises:
            GraphError: the service does not exist or has another type.
            FieldError: ``args`` does not fit the request.
        """
        return self.services.call(
            client, service, args, reply, type_name=type_name, timeout_s=timeout_s, path=path
        )

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
        """Answer a forwarded request (spec 3.3.9); see ``Services.respond`` for errors."""
        self.services.respond(client, service, request_id, result, values, path=path)

    def advertise_action(
        self,
        client: ClientId,
        action: str,
        type_name: str,
        provider: ActionProvider,
        *,
        status: bool = True,
    ) -> str:
        """Offer ``action`` of ``type_name``, provided by a client session (spec 3.3.10, D15).

        ``status``: the graph publishes the action's ``_action/status`` topic
        (``action_status``); a link that mirrors a remote action server passes
        False, the server publishing its own.

        Raises:
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
        """
        actiontype = self.registry.action(type_name)
        name = resolve_name(action)
        self.nodes.name_of(client)
        self.offer_action(
            ActionEntry(name, action, type_name, actiontype, client, provider=provider),
            status=status,
        )
        return actiontype.name

    def unadvertise_action(self, client: ClientId, action: str) -> None:
        """Withdraw ``action`` and its cancel service; its goals abort (spec 3.3.11).

        Raises:
            GraphError: ``client`` does not provide it.
        """
        entry = self.actions.owned(client, action)
        self.actions.unadvertise(client, action)
        with contextlib.suppress(GraphError):  # replaced by another participant meanwhile
            self.services.unadvertise(client, cancel_service_name(entry.name))
        if entry.status is not None:
            self.unadvertise(client, entry.status.topic)

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
        """Send the goal ``args`` to ``action`` (spec 3.3.12, D4, D18).

        ``done(status, result, values)`` runs once; ``feedback``, when given,
        gets each feedback message. ``request_id``: the caller's id of the goal,
        by which any client may cancel it and which lets it outlive its caller
        (``Actions.send_goal``, D35).

        Raises:
            GraphError: the action does not exist.
            FieldError: ``args`` does not fit the goal.
        """
        return self.actions.send_goal(
            client, action, args, done, feedback, path=path, request_id=request_id
        )

    def cancel_action_goal(self, client: ClientId, action: str, request_id: str) -> None:
        """Ask to cancel the goal its caller named ``request_id``, for ``client`` (D35).

        Raises:
            GraphError: warning when no such goal is in flight.
        """
        self.actions.cancel(action, request_id)

    def action_feedback(
        self,
        client: ClientId,
        action: str,
        goal_id: str | int | None,
        values: object,
        *,
        path: str = "$",
    ) -> None:
        """Feedback from the provider (spec 3.3.14); see ``Actions.feedback``."""
        self.actions.feedback(client, action, goal_id, values, path=path)

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
        """The provider's result (spec 3.3.15, D18); see ``Actions.result``."""
        self.actions.result(client, action, goal_id, result, values, status=status, path=path)

    def offer_action(self, entry: ActionEntry, *, status: bool = True) -> None:
        """Advertise ``entry`` with its cancel service (a client's or in-process provider's).

        ROS 2 action servers also answer ``<action>/_action/cancel_goal``, which
        roslib's ``Action.cancelAllGoals`` calls; it belongs to the same provider.
        With ``status`` (ROS 2), the provider also publishes
        ``<action>/_action/status``, latched (``action_status``).

        Raises:
            GraphError: a client tried to take a name of the server's (D15).
        """
        replaced = self.actions.entries.get(entry.name)
        self.actions.advertise(entry)
        if replaced is not None and replaced.status is not None and replaced.owner != entry.owner:
            self.unadvertise(replaced.owner, replaced.status.topic)  # its status goes with it
        service = cancel_service_name(entry.name)
        srvtype = self.registry.service(CANCEL_GOAL_TYPE)
        handler = cancel_goals_handler(entry)
        self.services.advertise(
            ServiceEntry(service, service, srvtype, entry.owner, handler=handler)
        )
        if status and self.registry.dialect is Dialect.ROS2:
            topic = status_topic(entry.name)
            self.advertise(entry.owner, topic, GOAL_STATUS_ARRAY, latch=True)
            entry.status = StatusBoard(topic, entry.owner, self._publish_status, self.clock.wall)

    def _publish_status(self, client: ClientId, topic: str, msg: Message) -> None:
        """Deliver one ``GoalStatusArray`` of an action, latched, if its provider still has it."""
        with contextlib.suppress(GraphError):  # the provider went meanwhile
            self.publish_local(client, topic, msg, True)

    # ---- in-process participants and internals ----------------------------------

    def publish_local(
        self,
        client: ClientId,
        topic: str,
        msg: Message | None,
        latch: bool,
        wire: bytes | None = None,
        lifespan: float = 0.0,
    ) -> MessageEvent:
        """Deliver an already-converted message from an in-process publisher.

        ``wire``: ``msg`` in the dialect's wire serialization as it arrived (a
        link's sample, a bag's record), which subscribers sending that form pass
        on as it is (``MessageEvent.wire``); the caller vouches that it is ``msg``.
        ``msg`` None: the message is ``wire`` alone, decoded on first use
        (``MessageEvent.msg``). ``lifespan``: how long a subscriber's queue keeps
        it behind newer messages (``MessageEvent.lifespan``; a link's samples).

        Returns:
            the event its subscribers got.

        Raises:
            GraphError: ``client`` does not publish ``topic`` (any more).
        """
        entry = self._published_by(client, topic)
        return self.deliver(entry, msg, latch, client, wire, lifespan)  # positional: per message

    def publish_local_many(
        self,
        client: ClientId,
        topic: str,
        msgs: Sequence[Message | None],
        wires: Sequence[bytes | None],
        lifespan: float = 0.0,
    ) -> list[MessageEvent]:
        """``publish_local`` of a run of messages, not latched, in order (``deliver_many``).

        Returns:
            the events its subscribers got.

        Raises:
            GraphError: ``client`` does not publish ``topic`` (any more).
        """
        return self.deliver_many(self._published_by(client, topic), msgs, client, wires, lifespan)

    def _published_by(self, client: ClientId, topic: str) -> Topic:
        """The topic ``topic``, which ``client`` publishes.

        Raises:
            GraphError: it does not (any more).
        """
        entry = self.topics.get(topic)
        if entry is None or client not in entry.publishers:
            raise GraphError(f"the publisher of {topic} was closed")
        return entry

    def deliver(
        self,
        entry: Topic,
        msg: Message | None,
        latch: bool,
        client: ClientId,
        wire: bytes | None = None,
        lifespan: float = 0.0,
    ) -> MessageEvent:
        """Deliver a message on ``entry`` from ``client``, one of its publishers.

        ``publish_local`` without finding the topic by name: for a caller that
        holds the ``Topic`` and has checked that ``client`` publishes on it
        (``LocalPublisher``, a call less per message of a burst). ``msg``,
        ``wire`` and ``lifespan`` as for ``publish_local``.

        Returns:
            the event its subscribers got.
        """
        if self._batch is not None:  # this turn's batch was published first
            self.flush()
        clock = self._clock
        codec = entry.codec  # (per message: no call)
        if codec is None:
            codec = entry.codec = codec_for(self.registry, entry.msgtype)
        # positional: keywords to a class cost a dict per call (0.5 us a message)
        event = MessageEvent(
            entry.name,
            entry.msgtype.name,
            msg,
            clock.monotonic(),
            clock.wall(),
            codec,
            wire,
            lifespan,
        )
        entry.fan_out(event, latch, client)
        if self.taps:
            self._tap(entry, event, client, latch)
        return event

    def deliver_many(
        self,
        entry: Topic,
        msgs: Sequence[Message | None],
        client: ClientId,
        wires: Sequence[bytes | None],
        lifespan: float = 0.0,
    ) -> list[MessageEvent]:
        """``deliver`` a run of messages of ``entry`` from ``client``, not latched, in order.

        ``msgs`` and ``wires`` pair up, as ``deliver``'s ``msg`` and ``wire``. Where
        every subscriber takes runs (``Topic.batchable``: ``BatchSink``), each gets
        the run in one call (``Topic.fan_out_batch``) and the events share this
        delivery's time (``MessageEvent.now`` and ``stamp``), as ``flush`` gives a
        turn's batch; otherwise each message is delivered as ``deliver`` does it.

        Returns:
            the events its subscribers got, in order.
        """
        if len(msgs) == 1:
            return [self.deliver(entry, msgs[0], False, client, wires[0], lifespan)]
        if self._batch is not None:  # this turn's batch was published first
            self.flush()
        if entry._calls is None:  # subscribers changed since the last delivery
            entry.sinks()
        if not entry.batchable:
            return [
                self.deliver(entry, msg, False, client, wire, lifespan)
                for msg, wire in zip(msgs, wires, strict=True)
            ]
        clock = self._clock
        now, stamp = clock.monotonic(), clock.wall()
        codec = entry.codec
        if codec is None:
            codec = entry.codec = codec_for(self.registry, entry.msgtype)
        name, type_name = entry.name, entry.msgtype.name
        events = [
            MessageEvent(name, type_name, msg, now, stamp, codec, wire, lifespan)
            for msg, wire in zip(msgs, wires, strict=True)
        ]
        entry.fan_out_batch(events)
        if self.taps:
            for event in events:
                self._tap(entry, event, client, False)
        return events

    def deliver_wire(self, entry: Topic, latch: bool, client: ClientId, wire: bytes) -> None:
        """``deliver`` a serialized message, or add it to this turn's batch.

        Batched (docs/embedding.md, "Batched delivery") while a server lends the
        loop (``serving``), the topic is ``batchable`` and the message not
        latched, with no taps (a link or a recorder sees each message as it
        comes); the batch is delivered when the loop's turn ends (``flush``),
        before anything else is delivered or subscribed, or once it holds
        ``BATCH_MAX_MESSAGES`` or ``BATCH_MAX_BYTES``. After a batch of one
        message, the next ``SOLO_AFTER_ONE`` go at once.
        """
        batchable = entry.batchable
        if not batchable and entry._calls is None:  # subscribers changed since the last one
            entry.sinks()
            batchable = entry.batchable
        batch = self._batch
        if batch is not None:
            if batchable and not latch:
                batch.append((entry, client, wire))
                self._batch_bytes += len(wire)
                if len(batch) >= BATCH_MAX_MESSAGES or self._batch_bytes >= BATCH_MAX_BYTES:
                    self.flush()
                return
        elif batchable and not latch and self._soon is not None and not self.taps:
            if self._solo <= 0:
                self._batch = [(entry, client, wire)]
                self._batch_bytes = len(wire)
                self._soon(self.flush)
                return
            self._solo -= 1
        self.deliver(entry, None, latch, client, wire)

    def flush(self) -> None:
        """Deliver this turn's batch now (``deliver_wire``); nothing if there is none.

        Each run of messages of one topic is given to each sink in one call
        (``Topic.fan_out_batch``), in publish order; its events carry the time
        of this delivery (``MessageEvent.now`` and ``stamp``).
        """
        batch = self._batch
        if batch is None:
            return
        self._batch = None
        if len(batch) == 1:
            self._solo = SOLO_AFTER_ONE
            entry, client, wire = batch[0]
            self.deliver(entry, None, False, client, wire)
            return
        clock = self._clock
        now, stamp = clock.monotonic(), clock.wall()
        start, count = 0, len(batch)
        while start < count:
            entry = batch[start][0]
            end = start + 1
            while end < count and batch[end][0] is entry:
                end += 1
            codec = entry.codec
            if codec is None:
                codec = entry.codec = codec_for(self.registry, entry.msgtype)
            name, type_name = entry.name, entry.msgtype.name
            events = [
                MessageEvent(name, type_name, None, now, stamp, codec, wire)
                for _, _, wire in batch[start:end]
            ]
            entry.fan_out_batch(events)  # still ``batchable``: subscribing delivers the batch first
            if self.taps:  # (one appeared during the turn)
                for (_, client, _), event in zip(batch[start:end], events, strict=True):
                    self._tap(entry, event, client, False)
            start = end

    def _tap(self, entry: Topic, event: MessageEvent, client: ClientId, latch: bool) -> None:
        for tap in self.taps:
            try:
                tap(entry, event, client, latch)
            except Exception:  # a broken tap must not fail the publisher
                _episodes.log(
                    logging.ERROR,
                    f"tap_failed {entry.name}",
                    "tap of %s failed",
                    entry.name,
                    exc_info=True,
                )

    def _topic(self, topic: str, msgtype: MessageType) -> Topic:
        name = resolve_name(topic)
        entry = self.topics.get(name)
        if entry is None:
            entry = self.topics[name] = Topic(name, msgtype)
        else:
            entry.check_type(msgtype)
        return entry

    def _collect(self, entry: Topic) -> None:
        if not entry.in_use and self.topics.get(entry.name) is entry:
            del self.topics[entry.name]

    def reserve_topic(self, name: str) -> None:
        """Keep topic ``name`` (or, ending in ``*``, every topic starting so) for in-process code.

        A client's ``advertise`` or ``publish`` on it is refused, so it cannot
        forge what the server publishes there (docs/limits.md).
        """
        if name.endswith("*"):
            self._reserved_prefixes += (resolve_name(name[:-1]) if name[:-1] else "/",)
        else:
            self._reserved_topics.add(resolve_name(name))

    def _check_reserved(self, client: ClientId, topic: str) -> None:
        if is_local(client):
            return
        name = resolve_name(topic)
        if name in self._reserved_topics or name.startswith(self._reserved_prefixes):
            raise GraphError(f"topic {topic} is reserved by the server")

    def local_client(self) -> ClientId:
        """A fresh participant id for in-process code (its services, calls and goals)."""
        return f"{LOCAL_PREFIX}{next(self._local_ids)}"


def _drop_last(items: list[_T], item: _T) -> None:
    """Remove the last entry of ``items`` that is ``item`` (identity, not equality)."""
    for index in range(len(items) - 1, -1, -1):
        if items[index] is item:
            del items[index]
            return
