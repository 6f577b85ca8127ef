"""What rosapi reports about the graph: topics, services, actions and nodes (REF §7.1).

Every function answers for one calling client (its ``Visibility``). Names come
back resolved and sorted; types in the canonical form of the dialect (D5).
Hidden names (a part starting with ``_``) are left out of listings, as ROS 2 does.
A name that cannot go on the wire (not valid Unicode; the protocol edge refuses
them, in-process code might not) is left out and logged, so one bad entry never
fails a listing for every client.
"""

from __future__ import annotations

import logging
import platform
from typing import TYPE_CHECKING

from rwt_protocol.errors import GraphError
from rwt_protocol.names import resolve_name

from ..ratelog import EpisodeLog
from ..types import Dialect
from .visibility import Visibility, is_hidden

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

    from rwt_protocol.ports import ClientId

    from ..graph import Graph
    from ..types.names import Kind

__all__ = [
    "action_servers",
    "action_type",
    "encodable",
    "node_details",
    "node_names",
    "publishers",
    "service_host",
    "service_node",
    "service_providers",
    "service_type",
    "services",
    "services_for_type",
    "subscribers",
    "topic_type",
    "topics",
    "topics_for_type",
]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message


def encodable(name: str) -> bool:
    """Whether ``name`` can be sent (valid Unicode); logs the ones that cannot."""
    if name.isascii():
        return True
    try:
        name.encode()
    except UnicodeEncodeError:
        if name not in _UNLISTED and len(_UNLISTED) < 100:  # one line per name, bounded
            _UNLISTED.add(name)
            _episodes.log(
                logging.WARNING,
                "unlisted",
                "event=unlisted reason='not valid Unicode' name=%a",
                name[:200],
            )
        return False
    return True


_UNLISTED: set[str] = set()


#: The topics of a ROS 1 actionlib server ``<ns>``; rosapi lists ``<ns>`` when all exist.
_ROS1_ACTION_TOPICS = ("goal", "cancel", "status", "feedback", "result")


def topics(graph: Graph, vis: Visibility) -> tuple[list[str], list[str]]:
    """Visible topics and their types, as parallel lists."""
    pairs = [
        (name, entry.msgtype.name)
        for name, entry in sorted(graph.topics.items())
        if _shows(name, vis.topic)
    ]
    return [name for name, _ in pairs], [type_name for _, type_name in pairs]


def _canonical(graph: Graph, type_name: str, kind: Kind) -> str | None:
    try:
        return graph.registry.canonical_name(type_name, kind)
    except GraphError:
        return None


def topics_for_type(graph: Graph, vis: Visibility, type_name: str) -> list[str]:
    """Visible topics of a message type, given in any spelling (D5)."""
    wanted = _canonical(graph, type_name, "msg")
    names, types = topics(graph, vis)
    return [name for name, found in zip(names, types, strict=True) if found == wanted]


def topic_type(graph: Graph, vis: Visibility, topic: str) -> str:
    """The type of a visible topic, ``""`` if there is none."""
    name = resolve_name(topic)
    entry = graph.topics.get(name)
    return entry.msgtype.name if entry is not None and vis.topic(name) else ""


def services(graph: Graph, vis: Visibility) -> list[str]:
    """Visible service names."""
    return sorted(name for name in graph.services.entries if _shows(name, vis.service))


def _shows(name: str, allowed: Callable[[str], bool]) -> bool:
    return not is_hidden(name) and allowed(name) and encodable(name)


def services_for_type(graph: Graph, vis: Visibility, type_name: str) -> list[str]:
    """Visible services of a service type, given in any spelling."""
    wanted = _canonical(graph, type_name, "srv")
    return [
        name for name in services(graph, vis) if graph.services.entries[name].srvtype.name == wanted
    ]


def service_type(graph: Graph, vis: Visibility, service: str) -> str:
    """The type of a visible service, ``""`` if there is none."""
    name = resolve_name(service)
    entry = graph.services.entries.get(name)
    return entry.srvtype.name if entry is not None and vis.service(name) else ""


def node_names(graph: Graph) -> list[str]:
    """Every node: of participants, and (ROS 2) of parameters."""
    return sorted(name for name in graph.nodes.names() | graph.params.nodes() if encodable(name))


def node_details(graph: Graph, vis: Visibility, node: str) -> tuple[list[str], ...]:
    """What a node subscribes to, publishes and provides (``NodeDetails`` order).

    Raises:
        GraphError: there is no such node.
    """
    name = resolve_name(node)
    if name not in node_names(graph):
        raise GraphError(f"node {node} does not exist")
    members = graph.nodes.clients_of(name)
    subscribing = [
        topic
        for topic, entry in sorted(graph.topics.items())
        if _shows(topic, vis.topic) and members.intersection(entry.subscribers)
    ]
    publishing = [
        topic
        for topic, entry in sorted(graph.topics.items())
        if _shows(topic, vis.topic) and members.intersection(entry.publishers)
    ]
    provided = sorted(
        service
        for service, entry in graph.services.entries.items()
        if _shows(service, vis.service) and entry.owner in members
    )
    return subscribing, publishing, provided


def _nodes_of(graph: Graph, clients: Iterable[ClientId]) -> list[str]:
    return sorted({graph.nodes.name_of(client) for client in clients})


def publishers(graph: Graph, vis: Visibility, topic: str) -> list[str]:
    """Nodes publishing a visible topic."""
    name = resolve_name(topic)
    entry = graph.topics.get(name)
    if entry is None or not vis.topic(name):
        return []
    return _nodes_of(graph, entry.publishers)


def subscribers(graph: Graph, vis: Visibility, topic: str) -> list[str]:
    """Nodes subscribed to a visible topic."""
    name = resolve_name(topic)
    entry = graph.topics.get(name)
    if entry is None or not vis.topic(name):
        return []
    return _nodes_of(graph, entry.subscribers)


def service_providers(graph: Graph, vis: Visibility, type_name: str) -> list[str]:
    """Nodes providing a visible service of a service type (REF §7.1: the request names a type)."""
    wanted = _canonical(graph, type_name, "srv")
    owners = [
        entry.owner
        for name, entry in graph.services.entries.items()
        if entry.srvtype.name == wanted and vis.service(name)
    ]
    return _nodes_of(graph, owners)


def _provider(graph: Graph, vis: Visibility, service: str) -> ClientId | None:
    name = resolve_name(service)
    entry = graph.services.entries.get(name)
    return entry.owner if entry is not None and vis.service(name) else None


def service_node(graph: Graph, vis: Visibility, service: str) -> str:
    """The node providing a visible service, ``""`` if none."""
    owner = _provider(graph, vis, service)
    return "" if owner is None else graph.nodes.name_of(owner)


def service_host(graph: Graph, vis: Visibility, service: str) -> str:
    """ROS 1: the host of a service's provider: a client's address, or this machine's name."""
    owner = _provider(graph, vis, service)
    if owner is None:
        return ""
    host = graph.nodes.host_of(owner)
    return host if host is not None else platform.node()


def action_servers(graph: Graph, vis: Visibility) -> list[str]:
    """Visible actions; in ROS 1 also the namespaces with all five actionlib topics."""
    found = {name for name in graph.actions.entries if vis.action(name) and encodable(name)}
    if graph.registry.dialect is Dialect.ROS1:
        for name in graph.topics:
            namespace, _, leaf = name.rpartition("/")
            if leaf == "goal" and namespace and vis.action(namespace):
                wanted = (f"{namespace}/{topic}" for topic in _ROS1_ACTION_TOPICS)
                if encodable(namespace) and all(
                    topic in graph.topics and vis.topic(topic) for topic in wanted
                ):
                    found.add(namespace)
    return sorted(found)


def action_type(graph: Graph, vis: Visibility, action: str) -> str:
    """The type of a visible action, ``""`` if there is none."""
    name = resolve_name(action)
    entry = graph.actions.entries.get(name)
    return entry.actiontype.name if entry is not None and vis.action(name) else ""
