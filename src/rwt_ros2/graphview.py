"""A snapshot of the ROS 2 graph as rclpy sees it, and the QoS a subscription needs.

Taken on a worker thread (rcl's graph queries are thread safe) every sweep;
the link compares it with what it mirrored. The link's own node is left out:
its endpoints are the local graph's, shared outward.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from rwt_graph.link import DEFAULT_DEPTH

from .qos import rclpy_qos

if TYPE_CHECKING:
    from rwt_protocol.qos import QosProfile

    from .node import RosNode

__all__ = [
    "ACTION_PART",
    "INWARD_DEPTH",
    "MAX_PUBLISHER_DEPTH",
    "Endpoint",
    "Qos",
    "RosGraph",
    "digest",
    "publisher_depth",
    "rclpy_profile",
    "snapshot",
    "subscription_qos",
]

UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"
"""The node name rmw gives an endpoint discovered before its node: such an
endpoint waits for the next sweep, so rosapi never lists a made-up node."""

ACTION_PART = "/_action/"
"""In the names of an action's own topics and services, which its action stands for."""


@dataclass(frozen=True)
class Qos:
    """The QoS of an endpoint, as far as matching goes.

    Attributes:
        reliable: reliable, not best effort.
        transient_local: transient local durability, not volatile.
        depth: history depth (KEEP_LAST); 0 for KEEP_ALL or unknown.
        asked: the whole profile a client of the graph asked for (protocol 2.1.0,
            ``rwt_ros2.qos``), which the link's endpoint takes as it is; None: the
            link's own rules (the three fields above).
    """

    reliable: bool = True
    transient_local: bool = False
    depth: int = DEFAULT_DEPTH
    asked: QosProfile | None = None


@dataclass(frozen=True)
class Endpoint:
    """A publisher or subscription of another node."""

    kind: str  # "publisher" or "subscription"
    topic: str
    type_name: str
    node: str  # fully qualified
    gid: bytes
    qos: Qos
    type_hash: str = ""  # RIHS01_<hex> as the middleware reports it; "" when it does not


@dataclass
class RosGraph:
    """The ROS 2 graph without the link's own node.

    Attributes:
        nodes: fully qualified names of the other nodes.
        endpoints: publishers and subscriptions by gid.
        services: (node, service) -> type, servers only (an action's own
            services left out: the action stands for them).
        actions: (node, action) -> type, servers only.
        own_publishers: the publishers of the link's own node (its rcl ``/rosout``
            one, and the link's), for the QoS of its subscriptions only.
    """

    nodes: set[str] = field(default_factory=set)
    endpoints: dict[bytes, Endpoint] = field(default_factory=dict)
    services: dict[tuple[str, str], str] = field(default_factory=dict)
    actions: dict[tuple[str, str], str] = field(default_factory=dict)
    own_publishers: list[Endpoint] = field(default_factory=list)


def _fqn(node: str, namespace: str) -> str:
    return f"{namespace.rstrip('/')}/{node}"


def _qos(profile: Any, rclpy_qos: Any) -> Qos:
    reliable = profile.reliability != rclpy_qos.ReliabilityPolicy.BEST_EFFORT
    transient = profile.durability == rclpy_qos.DurabilityPolicy.TRANSIENT_LOCAL
    keep_last = profile.history != rclpy_qos.HistoryPolicy.KEEP_ALL
    return Qos(reliable, transient, int(profile.depth) if keep_last else 0)


def snapshot(ros: RosNode) -> RosGraph:
    """The graph now (blocking: run it on a worker thread)."""
    graph = RosGraph()
    _read_nodes(ros, graph)
    _read_endpoints(ros, graph)
    return graph


def digest(ros: RosNode) -> tuple[object, ...]:
    """The graph's node, topic and service names with their types (blocking: a worker thread).

    Three rcl queries, without the per-topic ones of ``snapshot``: cheap enough
    to read every ``GRAPH_POLL_S`` and sweep when it changes (a node came or
    went, a topic or service appeared). A new endpoint of a known topic shows
    at the next periodic sweep.
    """
    node = ros.node
    return (
        sorted(node.get_node_names_and_namespaces()),
        sorted((name, tuple(types)) for name, types in node.get_topic_names_and_types()),
        sorted((name, tuple(types)) for name, types in node.get_service_names_and_types()),
    )


def _read_nodes(ros: RosNode, graph: RosGraph) -> None:
    """The other nodes, their service servers and action servers.

    A node that leaves between being listed and being asked of (rcl then raises) is
    left out, as if it had left before: the next sweep sees the graph as it is.
    """
    from rclpy.action.graph import get_action_server_names_and_types_by_node  # noqa: PLC0415

    node = ros.node
    for name, namespace in node.get_node_names_and_namespaces():
        fqn = _fqn(name, namespace)
        if fqn == ros.fqn:
            continue
        try:
            services = node.get_service_names_and_types_by_node(name, namespace)
            actions = get_action_server_names_and_types_by_node(node, name, namespace)
        except RuntimeError:  # rclpy's RCLError: the node left since it was listed
            continue  # as if it had left before: the next sweep sees what is there
        graph.nodes.add(fqn)
        for service, types in services:
            if types and ACTION_PART not in service:
                graph.services[(fqn, service)] = types[0]
        for action, types in actions:
            if types:
                graph.actions[(fqn, action)] = types[0]


def _read_endpoints(ros: RosNode, graph: RosGraph) -> None:
    """Every topic's publishers and subscriptions, with their QoS and type hash."""
    import rclpy.qos as rclpy_qos  # noqa: PLC0415

    node = ros.node
    for topic, _types in node.get_topic_names_and_types():
        if ACTION_PART in topic:
            continue
        try:
            infos = [("publisher", i) for i in node.get_publishers_info_by_topic(topic)]
            infos += [("subscription", i) for i in node.get_subscriptions_info_by_topic(topic)]
        except RuntimeError:  # rclpy's RCLError: the topic's last endpoint left meanwhile
            continue
        for kind, info in infos:
            if info.node_name == UNKNOWN_NODE:
                continue  # its node is not discovered yet: the next sweep has it
            gid = bytes(info.endpoint_gid)[:16]
            fqn = _fqn(info.node_name, info.node_namespace)
            qos = _qos(info.qos_profile, rclpy_qos)
            if fqn == ros.fqn:
                if kind == "publisher":
                    graph.own_publishers.append(Endpoint(kind, topic, "", fqn, gid, qos))
                continue
            hashed = info.topic_type_hash
            type_hash = f"RIHS01_{bytes(hashed.value).hex()}" if hashed.version == 1 else ""
            graph.endpoints[gid] = Endpoint(kind, topic, info.topic_type, fqn, gid, qos, type_hash)


INWARD_DEPTH = 100
"""The least history depth of the link's subscriptions: 20 ms of a 5 kHz topic.

The link's samples wait in its subscription's history until rclpy's executor
thread takes them, and that thread waits for the GIL while the event loop's
thread runs: up to the interpreter's switch interval (5 ms) each time, longer
under load. With ROS 2's default depth of 10 a 5 kHz topic overflowed the
history within 2 ms: the link's counters put all of the 5-21 % it lost there
(benchmarks/README.md, "ROS 2 bridge"). A deeper history holds the same samples
a moment longer and costs nothing while the link keeps up; a 1 MB image topic the
link cannot keep up with holds up to 100 MB in it. Fast DDS reports no depth for
other nodes' endpoints, so a publisher's own depth rarely raises it further."""


def subscription_qos(publishers: list[Qos]) -> Qos:
    """The QoS of the link's subscription that matches every one of ``publishers``.

    Reliable only if every publisher is (a reliable reader refuses a best
    effort writer); transient local only if every publisher is (a transient
    local reader refuses a volatile writer), so a late subscriber gets what
    ``/tf_static`` or ``/map`` kept; the deepest publisher's depth, at least
    ``INWARD_DEPTH``. No publisher: reliable, volatile, ``INWARD_DEPTH``.
    """
    if not publishers:
        return Qos(depth=INWARD_DEPTH)
    return Qos(
        reliable=all(q.reliable for q in publishers),
        transient_local=all(q.transient_local for q in publishers),
        depth=max([INWARD_DEPTH, *(q.depth for q in publishers)]),
    )


MAX_PUBLISHER_DEPTH = 1000
"""The deepest history the link gives a publisher toward ROS 2 (``publisher_depth``)."""


def publisher_depth(subscriptions: list[Qos]) -> int:
    """The history depth of the link's publisher of a topic with ``subscriptions``.

    The deepest reliable subscription's (KEEP_ALL: ``MAX_PUBLISHER_DEPTH``), at least
    ``DEFAULT_DEPTH`` and at most ``MAX_PUBLISHER_DEPTH``: a burst a web client
    publishes at once stays in the writer's history until that subscription has
    taken it, as it would from an rclpy publisher of the subscription's QoS (as
    rosbridge's ``queue_size``; docs/ros2.md). Best-effort subscriptions take what
    comes and ask for nothing.
    """
    deepest = max(
        (q.depth or MAX_PUBLISHER_DEPTH for q in subscriptions if q.reliable),
        default=DEFAULT_DEPTH,
    )
    return min(max(deepest, DEFAULT_DEPTH), MAX_PUBLISHER_DEPTH)


def rclpy_profile(qos: Qos) -> Any:
    """The ``rclpy.qos.QoSProfile`` of ``qos`` (a client's whole profile when it asked one)."""
    if qos.asked is not None:
        return rclpy_qos(qos.asked)
    from rclpy.qos import (  # noqa: PLC0415
        DurabilityPolicy,
        HistoryPolicy,
        QoSProfile,
        ReliabilityPolicy,
    )

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(qos.depth, 1),
        reliability=ReliabilityPolicy.RELIABLE if qos.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if qos.transient_local else DurabilityPolicy.VOLATILE
        ),
    )
