"""The link contract: how a graph is mirrored to and from another middleware.

A link (``rwt_zenoh``'s Zenoh link, ``rwt_ros2``'s rclpy link) attaches to a
``Graph`` through its port (``Graph.port``), as sessions do, and follows the
same rules, written here once:

- **Local and remote.** Every participant the link adds to the graph (an entity
  of the other middleware) has a client id starting with the link's prefix
  (``LinkRules.ours``); everything else is local. Only local entities are shared
  outward (``LinkRules.wanted``), and only local publishers' messages are
  forwarded (``LinkRules.forwards``, which the link's graph tap asks), so
  nothing that came in goes back out.
- **Private names.** Each server keeps its client counts and its rosapi to
  itself (``PRIVATE_NAMES``): rosapi already answers for the whole graph.
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
  by the topic's relay until the publisher is known (``Relays``).
- **Cleanup.** A remote entity that goes is released (``GraphCore.release``):
  its services fail their callers (D15), its latched message goes (D13). When
  the link stops, it releases every remote entity it mirrored.
"""

from __future__ import annotations

import enum
from typing import TYPE_CHECKING, Any, Protocol

from rwt_protocol.errors import RwtError

if TYPE_CHECKING:
    from collections.abc import Container

    from rwt_protocol.ports import ClientId, MessageEvent

    from .actions import ActionEntry
    from .graph import Graph
    from .topics import Topic

__all__ = [
    "DEFAULT_DEPTH",
    "LATCHED_DEPTH",
    "NULL_SINK",
    "PRIVATE_NAMES",
    "GraphLink",
    "Kind",
    "LinkRules",
    "Relays",
    "Wanted",
    "mirror_endpoint",
]

DEFAULT_DEPTH = 10
"""History depth of a plain topic's publisher (``rmw_qos_profile_default``:
reliable, volatile, keep last 10)."""

LATCHED_DEPTH = 1
"""History depth of a latched topic's publisher (reliable, transient local, keep
last 1: the last message for each late subscriber, D13)."""

PRIVATE_NAMES = ("/client_count", "/connected_clients", "/rosapi/*")
"""Names each server keeps to itself: its own client counts and its rosapi (which
already answers for the whole graph). ``*`` ends a prefix."""

#: Names remembered by ``LinkRules.is_private``; past it the memory starts over
#: (topic names come from clients, so the table must stay bounded).
PRIVATE_CACHE = 10_000


class Kind(enum.Enum):
    """The kinds of local entity a link shares."""

    PUBLISHER = "publisher"
    SUBSCRIPTION = "subscription"
    SERVICE = "service"


Wanted = dict[tuple[Kind, "ClientId", str], tuple[str, bool]]
"""Local entities to share: (kind, participant, name) -> (type name, latched)."""


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
        nothing that came in goes back out (no echo, no loops).
        """
        return not client.startswith(self.prefix) and not self.is_private(topic)

    def is_private(self, name: str) -> bool:
        """Whether ``name`` stays in this process; remembered, as taps ask per message."""
        private = self._private_names.get(name)
        if private is None:
            if len(self._private_names) >= PRIVATE_CACHE:
                self._private_names.clear()
            private = self._private_names[name] = matches_private(name, self.private)
        return private

    def wanted(self, graph: Graph) -> Wanted:
        """The local entities of ``graph`` to share outward, private names left out."""
        wanted: Wanted = {}
        for name, entry in graph.topics.items():
            if self.is_private(name):
                continue
            type_name = entry.msgtype.name
            for client, latched in entry.publishers.items():
                if not self.ours(client):
                    wanted[(Kind.PUBLISHER, client, name)] = (type_name, latched)
            for client in entry.subscribers:
                if not self.ours(client):
                    wanted[(Kind.SUBSCRIPTION, client, name)] = (type_name, False)
        for name, service in graph.services.entries.items():
            if not self.ours(service.owner) and not self.is_private(name):
                wanted[(Kind.SERVICE, service.owner, name)] = (service.srvtype.name, False)
        return wanted

    def local_actions(self, graph: Graph) -> dict[str, ActionEntry]:
        """The local action servers of ``graph`` to share outward, by name."""
        return {
            name: entry
            for name, entry in graph.actions.entries.items()
            if not self.ours(entry.owner) and not self.is_private(name)
        }


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
            topic; ``UnknownTypeError``...). ``kind`` is a service: ``ValueError``.
    """
    if kind is Kind.SERVICE:
        raise ValueError("a service is mirrored with its provider (GraphCore.advertise_service)")
    graph.nodes.bind(client, node)
    try:
        if kind is Kind.PUBLISHER:
            graph.port.advertise(client, topic, type_name, latch=latched)
        else:
            graph.port.subscribe(client, topic, type_name, NULL_SINK)
    except RwtError:
        graph.nodes.forget(client)
        raise


class Relays:
    """Stand-in publishers of samples that outran their publisher's discovery.

    A sample can arrive before the link has seen its publisher (rmw_zenoh's
    token, the ROS 2 graph's endpoint): the topic's relay, a participant of the
    link (``<prefix>relay:<topic>``) in ``node``, publishes it meanwhile. A
    relay goes once its topic's publishers are known, the topic is gone or the
    link no longer subscribes to it (``sweep``), and when the link stops (``close``).

    Args:
        graph: the linked graph.
        rules: the link's rules (its participant prefix).
        node: the node rosapi lists the relays in (the link's own).
    """

    def __init__(self, graph: Graph, rules: LinkRules, node: str) -> None:
        self._graph = graph
        self._rules = rules
        self._node = node
        self._relays: dict[str, ClientId] = {}

    def deliver(self, entry: Topic, publisher: ClientId | None, msg: dict[str, object]) -> None:
        """Publish ``msg``, a decoded sample of ``entry``'s topic, in the graph.

        By ``publisher``'s participant when the link mirrors it as a publisher of
        the topic (latched as it advertised), otherwise by the topic's relay.

        Raises:
            RwtError: the topic is reserved by the server, so no relay may
                publish there (``GraphError``); the sample is not the network's.
        """
        port = self._graph.port
        if publisher is not None:
            latched = entry.publishers.get(publisher)
            if latched is not None:
                port.publish_local(publisher, entry.name, msg, latch=latched)
                return
        relay = self._relays.get(entry.name)
        if relay is None:
            relay = f"{self._rules.prefix}relay:{entry.name}"
            mirror_endpoint(
                self._graph, relay, self._node, Kind.PUBLISHER, entry.name, entry.msgtype.name
            )
            self._relays[entry.name] = relay
        port.publish_local(relay, entry.name, msg, latch=False)

    def sweep(self, subscribed: Container[str]) -> None:
        """Release each relay no longer needed.

        A relay goes when its topic is gone, is not in ``subscribed`` (the topics
        the link receives) or has a publisher of the link's that is known now.
        """
        graph = self._graph
        for topic, relay in list(self._relays.items()):
            entry = graph.topics.get(topic)
            known = entry is not None and any(
                self._rules.ours(client) and client != relay for client in entry.publishers
            )
            if entry is None or known or topic not in subscribed:
                del self._relays[topic]
                graph.port.release(relay)

    def close(self) -> None:
        """Release every relay (the link stops)."""
        for relay in self._relays.values():
            self._graph.port.release(relay)
        self._relays.clear()


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
