"""One visibility rule for every listing of the graph (rwt_graph.visibility).

What a client may see follows its access rules, family by family; rwt's own
plumbing shows only when asked (``plumbing``), what a client connection holds
always (D47). Here on real changes of a graph's feed.
"""

from __future__ import annotations

from dataclasses import replace

from rwt_graph.feed import EntityKind, GraphChange
from rwt_graph.graph import Graph
from rwt_graph.nodes import Role
from rwt_graph.rosapi import install_rosapi
from rwt_graph.visibility import EVERYTHING, Visibility
from rwt_protocol.runtime.access import AccessPolicy


def _changes(graph: Graph) -> dict[str, GraphChange]:
    return {change.name: change for change in graph.port.feed.snapshot()[1]}


def test_plumbing_shows_only_when_asked_and_connections_always() -> None:
    graph = Graph()
    install_rosapi(graph)
    graph.create_publisher("/odom", "nav_msgs/msg/Odometry", node="/base")
    graph.port.advertise("ws:client#1", "/cmd", "std_msgs/msg/String")
    changes = _changes(graph)
    rosapi, odom, cmd = changes["/rosapi/topics"], changes["/odom"], changes["/cmd"]
    assert (rosapi.role, odom.role, cmd.role) == (Role.PLUMBING, Role.ROBOT, Role.CONNECTION)
    robot_only = replace(EVERYTHING, plumbing=False)
    assert [robot_only.sees(c) for c in (rosapi, odom, cmd)] == [False, True, True]
    assert all(EVERYTHING.sees(c) for c in (rosapi, odom, cmd))


def test_the_access_rules_decide_by_family() -> None:
    policy = AccessPolicy(topics=["/odom"], services=["/nothing"])
    visible = Visibility.of(policy)
    graph = Graph()
    install_rosapi(graph)
    graph.create_publisher("/odom", "nav_msgs/msg/Odometry")
    graph.create_publisher("/secret", "std_msgs/msg/String")
    graph.create_service("/lights", "std_srvs/srv/SetBool", lambda req: {"success": True})
    changes = _changes(graph)
    shown = {name for name, change in changes.items() if visible.sees(change)}
    assert "/odom" in shown and "/rosapi/topics" in shown
    assert "/secret" not in shown and "/lights" not in shown
    assert changes["/lights"].kind is EntityKind.SERVICE
    assert Visibility.of(AccessPolicy()) is EVERYTHING  # unrestricted: everything


def test_closing_rosapi_withdraws_its_services_and_the_nodes_parameter_services() -> None:
    graph = Graph()
    graph.params.declare("/robot", {"max_speed": 1.5})
    rosapi = install_rosapi(graph)
    names = set(graph.services.entries)
    assert {"/rosapi/topics", "/robot/list_parameters", "/robot/get_parameters"} <= names
    rosapi.close()
    left = set(graph.services.entries)
    assert not any(name.startswith("/rosapi/") or name.startswith("/robot/") for name in left)
    graph.create_service("/rosapi/topics", "rosapi_msgs/srv/Topics", lambda req: {})  # free again
