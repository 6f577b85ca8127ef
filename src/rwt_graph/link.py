"""The link contract: how a graph is mirrored to and from another middleware.

A link (``rwt_zenoh``'s Zenoh link, ``rwt_ros2``'s rclpy link) attaches to a
``Graph`` through its port (``Graph.port``), as sessions do, and follows the
same rules, written here once:

- **Local and remote.** Every participant the link adds to the graph (an entity
  of the other middleware) has a client id starting with the link's prefix
  (``LinkRules.ours``); everything else is local. Only local entities are shared
  outward (``exports.Exports``, which follows the graph's change feed), and only
  local publishers' messages are
  forwarded (``LinkRules.forwards``, which the link's graph tap asks), so
  nothing that came in goes back out.
- **Private names.** Each server keeps its client counts, its rosapi and its TF
  republisher to itself (``PRIVATE_NAMES``): rosapi already answers for the whole
  graph, and each republisher serves its own clients.
- **QoS.** A local publisher goes out reliable, volatile, keep last
  ``DEFAULT_DEPTH`` (ROS 2's default profile), or, once it latches, transient
  local, keep last ``LATCHED_DEPTH`` (a latched topic's profile, D13).
- **Remote entities.** A remote publisher is a graph advertiser of its type
  (latched when its durability is transient local), a remote subscription is a
  graph subscriber whose sink drops messages (``NULL_SINK``: the data travels
  on the other middleware), a remote service is a graph service provider. Each
  belongs to its remote node (``Nodes.bind``), so rosapi lists it there
  (``mirror_endpoint``).
- **Samples.** A sample from the other middleware is published in the graph by
  its publisher's participant; one that outran the discovery of its publisher
  by the topic's relay until the publisher is known (``Relays``), latched as
  the link knows its durability, and handed over to its publisher once known,
  so a late subscriber gets a latched sample whichever came first.
- **Backpressure.** A link hands its samples to the graph in batches, each
  between ``Graph.port.inflow.begin()`` and ``end()``. A delivery that pushed a
  local subscriber's outbox over its high watermark holds back its topic
  (``topic_holds.TopicHolds``): that topic's later samples wait in the link,
  in order, until the outbox is under its low watermark, within the hold
  budget of the remote publisher whose sample congested it, as a publishing
  connection's reader waits on its own (docs/limits.md, D61); the
  link's queue then holds the other middleware back. Every other topic, and
  every event that is no sample, goes on meanwhile: a slow reader of one topic
  holds no other. Without a server the gate is open (``OPEN_GATE``).
  Outward, a link whose own queue for the other middleware (a ``Backlog``)
  passes its high watermark during a publish says so to
  ``Graph.port.outflow.congested``; the publishing connection's reader then
  waits, within the link's hold budget, until the queue is under its low
  watermark, so a burst faster than the other middleware takes it is held back
  at its source, not dropped. An in-process publisher is not held
  (``OPEN_OUTFLOW`` without a server).
- **Cleanup.** A remote entity that goes is released (``GraphCore.release``):
  its services fail their callers (D15), its latched message goes (D13). When
  the link stops, it releases every remote entity it mirrored.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from rwt_protocol.errors import RwtError

from .action_status import STATUS_SUFFIX
from .feed import EntityKind

if TYPE_CHECKING:
    from collections.abc import Callable, Container, Sequence

    from rwt_protocol.ports import ClientId, MessageEvent

    from .graph import Graph
    from .topics import Topic

__all__ = [
    "DEFAULT_DEPTH",
    "HELD_SOURCES",
    "LATCHED_DEPTH",
    "NULL_SINK",
    "OPEN_GATE",
    "OPEN_OUTFLOW",
    "PRIVATE_NAMES",
    "RELAY_WAIT_SWEEPS",
    "Backlog",
    "GraphLink",
    "InflowGate",
    "InflowHold",
    "Kind",
    "LinkRules",
    "OutflowGate",
    "Relays",
    "mirror_endpoint",
]

DEFAULT_DEPTH = 10
"""History depth of a plain topic's publisher (``rmw_qos_profile_default``:
reliable, volatile, keep last 10)."""

LATCHED_DEPTH = 1
"""History depth of a latched topic's publisher (reliable, transient local, keep
last 1: the last message for each late subscriber, D13)."""

PRIVATE_NAMES = (
    "/client_count",
    "/connected_clients",
    "/rosapi/*",
    "/tf2_web_republisher",
    "/tf2_web_republisher/*",
    "/republish_tfs",
)
"""Names each server keeps to itself: its own client counts, its rosapi (which
already answers for the whole graph) and its TF republisher's action, service and
actionlib topics (``rwt_graph.tf.install``; each server answers its own clients from
the ``/tf`` it shares). ``*`` ends a prefix."""

#: Names remembered by ``LinkRules.is_private``; past it the memory starts over
#: (topic names come from clients, so the table must stay bounded).
PRIVATE_CACHE = 10_000


Kind = EntityKind
"""The kinds of entity a link shares and mirrors: the change feed's (``feed.EntityKind``)."""


class _NullSink:
    """The sink of a remote subscription: its messages travel on the other middleware.

    ``drops_messages`` tells ``Topic.fan_out`` not to call it at all.
    """

    drops_messages = True

    def on_message(self, event: MessageEvent) -> None:
        """Drop the message."""


NULL_SINK = _NullSink()
"""The ``TopicSink`` of every remote subscription a link mirrors."""


class LinkRules:
    """The mirroring rules of one link (see the module text).

    Args:
        prefix: the client-id prefix of the link's participants (``"zenoh:"``).
        private: names never shared (``PRIVATE_NAMES``; ``*`` ends a prefix).
    """

    def __init__(self, prefix: str, private: tuple[str, ...] = PRIVATE_NAMES) -> None:
        self.prefix = prefix
        self.private = private
        self._private_names: dict[str, bool] = {}

    def ours(self, client: ClientId) -> bool:
        """Whether ``client`` is one of the link's participants (it came from outside)."""
        return client.startswith(self.prefix)

    def forwards(self, client: ClientId, topic: str) -> bool:
        """Whether a message ``client`` published on ``topic`` goes out (the links' taps).

        Only local publishers' messages on names that are not private do, so
        nothing that came in goes back out (no echo, no loops). Nor does an
        action's ``_action/status``: a link that serves the action publishes its
        own (``exports.offered_by_links``), and the graph's would come out twice.
        """
        return (
            not client.startswith(self.prefix)
            and not self.is_private(topic)
            and not topic.endswith(STATUS_SUFFIX)
        )

    def is_private(self, name: str) -> bool:
        """Whether ``name`` stays in this process; remembered, as taps ask per message."""
        private = self._private_names.get(name)
        if private is None:
            if len(self._private_names) >= PRIVATE_CACHE:
                self._private_names.clear()
            private = self._private_names[name] = matches_private(name, self.private)
        return private


def matches_private(name: str, private: tuple[str, ...]) -> bool:
    """Whether ``name`` is one of ``private`` (an entry ending ``*`` is a prefix)."""
    for pattern in private:
        if pattern.endswith("*"):
            if name.startswith(pattern[:-1]):
                return True
        elif name == pattern:
            return True
    return False


def mirror_endpoint(
    graph: Graph,
    client: ClientId,
    node: str,
    kind: Kind,
    topic: str,
    type_name: str,
    *,
    latched: bool = False,
) -> None:
    """Make a remote publisher or subscription a participant of ``graph`` (module text).

    ``client`` belongs to ``node``; a publisher advertises ``type_name``
    (latched when its durability is transient local), a subscription subscribes
    with ``NULL_SINK``. A refused entity leaves no node binding behind.

    Raises:
        RwtError: the graph refuses it (``GraphError``: another type, a reserved
            topic; ``UnknownTypeError``...). ``kind`` is a service or an
            action: ``ValueError``.
    """
    if kind not in (Kind.PUBLISHER, Kind.SUBSCRIPTION):
        raise ValueError(f"a {kind.value} is mirrored with its provider (GraphCore.advertise_*)")
    graph.nodes.bind(client, node)
    try:
        if kind is Kind.PUBLISHER:
            graph.port.advertise(client, topic, type_name, latch=latched)
        else:
            graph.port.subscribe(client, topic, type_name, NULL_SINK)
    except RwtError:
        graph.nodes.forget(client)
        raise


HELD_SOURCES = 8
"""Unknown publishers of a topic whose last sample its relay keeps for the hand-over
(``Relays``); past it the oldest is forgotten (GIDs come from the network)."""

RELAY_WAIT_SWEEPS = 10
"""Sweeps a relay stays, once a publisher of its topic is known, for the publisher
of a sample it holds that is not known yet (counted from its last sample): the
publishers of a topic need not all be discovered at the same sweep."""


@dataclass(eq=False)
class _Relay:
    """A topic's relay and what it relayed from publishers not yet known.

    ``held``: source GID -> (the last sample relayed from it, the topic's
    latched message right after that sample); ``idle``: sweeps since its last sample.
    """

    client: ClientId
    held: dict[bytes, tuple[MessageEvent, MessageEvent | None]] = field(default_factory=dict)
    idle: int = 0


class Relays:
    """Stand-in publishers of samples that outran their publisher's discovery.

    A sample can arrive before the link has seen its publisher (rmw_zenoh's
    token, the ROS 2 graph's endpoint): the topic's relay, a participant of the
    link (``<prefix>relay:<topic>``) in ``node``, publishes it meanwhile. A
    relay goes once its topic's publishers are known, the topic is gone or the
    link no longer subscribes to it (``sweep``), and when the link stops (``close``).

    Durability (D13): a sample the link knows to be transient local (it came on
    a transient-local subscription, which only transient-local publishers
    match) is latched by the relay at once, so a subscriber that comes before
    the publisher is known gets it. When the relay goes because its publisher
    is known, the last sample it relayed from a publisher that latches becomes
    that publisher's latched message (``Topic.keep``, not delivered again),
    unless a later latched message took its place; so a latched sample that
    came early is not lost to late subscribers, whatever the link knew of it.

    Args:
        graph: the linked graph.
        rules: the link's rules (its participant prefix).
        node: the node rosapi lists the relays in (the link's own).
        publisher_of: the participant the link mirrors for the publisher with
            this GID, or None while the link does not know it.
    """

    def __init__(
        self,
        graph: Graph,
        rules: LinkRules,
        node: str,
        publisher_of: Callable[[bytes], ClientId | None],
    ) -> None:
        self._graph = graph
        self._rules = rules
        self._node = node
        self._publisher_of = publisher_of
        self._relays: dict[str, _Relay] = {}

    def deliver(
        self,
        entry: Topic,
        source: bytes | None,
        msg: dict[str, object],
        *,
        latched: bool = False,
        wire: bytes | None = None,
        lifespan: float = 0.0,
    ) -> None:
        """Publish ``msg``, a decoded sample of ``entry``'s topic, in the graph.

        ``wire`` is the sample as it came (its CDR), passed on with the message
        (``MessageEvent.wire``) so that subscribers sending CDR do not serialize it again.
        ``lifespan``: how long subscribers' queues keep it behind newer samples
        (``MessageEvent.lifespan``).

        By the participant of ``source`` (its publisher's GID) when the link
        mirrors it as a publisher of the topic (latched as it advertised),
        otherwise by the topic's relay, latched when ``latched`` (the link knows
        the sample is transient local).

        Raises:
            RwtError: the topic is reserved by the server, so no relay may
                publish there (``GraphError``); the sample is not the network's.
        """
        port = self._graph.port
        publisher = None if source is None else self._publisher_of(source)
        if publisher is not None:
            latches = entry.publishers.get(publisher)
            if latches is not None:
                port.publish_local(
                    publisher, entry.name, msg, latch=latches, wire=wire, lifespan=lifespan
                )
                return
        relay = self._relay(entry)
        event = port.publish_local(
            relay.client, entry.name, msg, latch=latched, wire=wire, lifespan=lifespan
        )
        self._relayed(relay, source, event, entry)

    def deliver_many(
        self,
        entry: Topic,
        source: bytes | None,
        msgs: Sequence[dict[str, object]],
        wires: Sequence[bytes | None],
        *,
        latched: bool = False,
        lifespan: float = 0.0,
    ) -> None:
        """``deliver`` a run of one publisher's samples of ``entry``, in order.

        ``msgs`` and ``wires`` pair up. Unlatched, the run reaches each subscriber
        in one call where they take runs (``GraphCore.deliver_many``); a latched
        one goes sample by sample, each kept as ``deliver`` keeps it.

        Raises:
            RwtError: as ``deliver``.
        """
        port = self._graph.port
        publisher = None if source is None else self._publisher_of(source)
        if publisher is not None:
            latches = entry.publishers.get(publisher)
            if latches is not None and not latches:
                port.publish_local_many(publisher, entry.name, msgs, wires, lifespan)
                return
        if latched or publisher is not None:
            for msg, wire in zip(msgs, wires, strict=True):
                self.deliver(entry, source, msg, latched=latched, wire=wire, lifespan=lifespan)
            return
        relay = self._relay(entry)
        events = port.publish_local_many(relay.client, entry.name, msgs, wires, lifespan)
        self._relayed(relay, source, events[-1], entry)

    def _relay(self, entry: Topic) -> _Relay:
        """The relay of ``entry``'s topic, made (and mirrored as a publisher) on first use."""
        relay = self._relays.get(entry.name)
        if relay is None:
            client = f"{self._rules.prefix}relay:{entry.name}"
            mirror_endpoint(
                self._graph, client, self._node, Kind.PUBLISHER, entry.name, entry.msgtype.name
            )
            relay = self._relays[entry.name] = _Relay(client)
        return relay

    def _relayed(
        self, relay: _Relay, source: bytes | None, event: MessageEvent, entry: Topic
    ) -> None:
        """Note that ``relay`` published ``event``, the newest sample of ``source``."""
        relay.idle = 0
        if source is not None:
            held = relay.held
            held.pop(source, None)
            if len(held) >= HELD_SOURCES:
                del held[next(iter(held))]
            held[source] = (event, entry.latched)

    def sweep(self, subscribed: Container[str], *, tick: bool = True) -> None:
        """Release each relay no longer needed, handing its latched sample over.

        A relay goes when its topic is gone, is not in ``subscribed`` (the topics
        the link receives) or has a publisher of the link's that is known now;
        in the last case not while the publisher of a sample that could still
        be latched is unknown, for up to ``RELAY_WAIT_SWEEPS`` sweeps that
        ``tick`` (a link's periodic ones; not those a graph change asked for).
        """
        graph = self._graph
        for topic, relay in list(self._relays.items()):
            entry = graph.topics.get(topic)
            if entry is not None and topic in subscribed:
                if not any(
                    self._rules.ours(client) and client != relay.client
                    for client in entry.publishers
                ):
                    continue  # no publisher known yet
                relay.idle += tick
                if relay.idle <= RELAY_WAIT_SWEEPS and self._awaits(entry, relay):
                    continue
            del self._relays[topic]
            if entry is not None:
                self._hand_over(entry, relay)
            graph.port.release(relay.client)

    def _awaits(self, entry: Topic, relay: _Relay) -> bool:
        """Whether ``relay`` holds a sample that could still be latched, of an unknown publisher."""
        return any(
            entry.latched is after and self._publisher_of(source) is None
            for source, (_, after) in relay.held.items()
        )

    def _hand_over(self, entry: Topic, relay: _Relay) -> None:
        """Make the newest sample ``relay`` relayed from a known latching publisher its latched one.

        Only while no later latched message has taken its place (the topic's
        latched message is still the one that followed the sample).
        """
        for source, (event, after) in reversed(relay.held.items()):
            if entry.latched is not after:
                continue  # another latched message came after it
            publisher = self._publisher_of(source)
            if publisher is not None and entry.publishers.get(publisher):
                entry.keep(event, publisher)
                return

    def close(self) -> None:
        """Release every relay (the link stops)."""
        for relay in self._relays.values():
            self._graph.port.release(relay.client)
        self._relays.clear()


class InflowHold(Protocol):
    """The subscribers some deliveries congested, for a link to wait for."""

    async def wait(self) -> None:
        """Wait until they are under their low watermarks, each within its hold budget."""
        ...


class InflowGate(Protocol):
    """Backpressure for messages a link delivers from outside (no connection's reader).

    The transports install theirs on the graph they serve (``GraphCore.inflow``):
    deliveries between ``begin`` and ``end`` note every subscriber whose outbox
    they pushed over its high watermark, ``end`` writes out what they queued, and
    ``take_hold`` hands over what was noted, for the link to hold the topic back
    until those outboxes are under their low watermark, each within its hold
    budget (docs/limits.md, "Backpressure"), as a publishing connection's
    reader is held.
    """

    def begin(self) -> None:
        """A batch of deliveries starts (on the event loop, no await until ``end``)."""
        ...

    def end(self) -> None:
        """The batch ended: write out what it queued."""
        ...

    def congested(self) -> bool:
        """Whether a delivery since the last ``take_hold`` congested a subscriber.

        A link asks after each delivery, so a held topic overshoots a
        subscriber's high watermark by one message, not by a batch, and stays
        under its send buffer limit.
        """
        ...

    def take_hold(self, publisher: ClientId | None = None) -> InflowHold | None:
        """What the deliveries since the last call congested, to wait for; None if nothing.

        ``publisher``: the participant whose sample congested them (a remote
        publisher the link mirrors): the wait is charged to that publisher's hold
        budget, as a local publisher's reader is charged for the subscribers it
        congests; None (a relay's sample, a link that cannot tell): to the
        links' own (D61).
        """
        ...


class _OpenGate:
    """No transport serves the graph: nothing to write out or wait for."""

    def begin(self) -> None:
        pass

    def end(self) -> None:
        pass

    def congested(self) -> bool:
        return False

    def take_hold(self, publisher: ClientId | None = None) -> InflowHold | None:
        return None


OPEN_GATE: InflowGate = _OpenGate()
"""The gate of a graph no server serves (an embedded graph): holds nothing."""


class Backlog(Protocol):
    """A link's queue of local samples waiting for the other middleware (thread-safe).

    Local publishers fill it on the event loop; the link's own thread empties it
    as the other middleware takes the samples (a Zenoh ``put`` with congestion
    control BLOCK waits while the network does not).
    """

    @property
    def queued_bytes(self) -> int:
        """Bytes waiting now."""
        ...

    @property
    def water_marks(self) -> tuple[int, int]:
        """(high, low) watermarks in bytes: readers wait from high until under low."""
        ...

    def watch(self, on_take: Callable[[bool], None] | None) -> None:
        """Run ``on_take(caught_up)`` on the event loop as samples go out.

        ``caught_up`` says the queue was empty then; that call always comes, the
        others may be spaced out (the Zenoh outbox: at most one per 10 ms), as
        each wakes the loop. ``None`` stops the calls: they run only from a
        congestion until the queue empties.
        """
        ...


class OutflowGate(Protocol):
    """Backpressure for the local publishers whose messages fill a link's ``Backlog``.

    The transports install theirs on the graph they serve (``GraphCore.outflow``):
    a backlog reported congested while a reader handles its batch of frames is
    waited for after the batch, as a congested subscriber is (docs/limits.md,
    "Backpressure"), within a hold budget of its own.
    """

    def congested(self, backlog: Backlog) -> None:
        """A local publish just took ``backlog`` over its high watermark (on the event loop)."""
        ...


class _OpenOutflow:
    """No transport serves the graph: its publishers are never held."""

    def congested(self, backlog: Backlog) -> None:
        pass


OPEN_OUTFLOW: OutflowGate = _OpenOutflow()
"""The outflow gate of a graph no server serves: holds no publisher."""


class GraphLink(Protocol):
    """What every link offers: run it on the graph's event loop until cancelled.

    ``run`` mirrors (see the module text) until its task is cancelled, then
    withdraws everything it shared and releases every remote entity it mirrored.
    """

    graph: Graph
    rules: LinkRules

    async def run(self, *, task_status: Any) -> None:
        """Link until cancelled; ``task_status`` (anyio's) is told once linked."""
        ...
