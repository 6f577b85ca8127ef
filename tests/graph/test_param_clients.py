"""What clients set in the parameter store: charged to them, on nodes they may use (D34).

A client is a connection of the graph (``Nodes.attach`` gives it ``/rwt_client_<n>``);
the store charges what it sets to it within ``CLIENT_SHARE`` and releases it when the
graph forgets the client (``GraphCore.release``).
"""

from __future__ import annotations

import pytest

from rwt_graph.graph import Graph
from rwt_graph.parameters.store import (
    SERVER_NODES,
    ParameterError,
    Parameters,
    ParameterStoreFullError,
)
from rwt_graph.types import Dialect, TypeRegistry


def small_graph(dialect: Dialect = Dialect.ROS2, max_params: int = 80) -> Graph:
    """A graph whose store holds ``max_params`` (a client's share: a tenth), with a robot node."""
    graph = Graph(TypeRegistry(dialect))
    graph.params = Parameters(
        dialect, max_params=max_params, max_bytes=8000, client_share=0.1, nodes=graph.nodes
    )
    graph.create_publisher("/robot/state", "std_msgs/msg/String", node="/robot")
    return graph


def test_a_client_is_charged_within_its_share_and_the_others_keep_their_room() -> None:
    graph = small_graph()
    params = graph.params
    a, b = "ws:a#1", "ws:b#2"
    mine, theirs = graph.nodes.attach(a), graph.nodes.attach(b)
    share = params.max_client_params
    assert share == 8
    for n in range(share // 2):  # on its own node and on the robot's: one share for both
        params.set(f"{mine}:p{n}", n, client=a)
        params.set(f"/robot:a{n}", n, client=a)
    with pytest.raises(ParameterStoreFullError, match=r"this client holds its share .*\(8 parame"):
        params.set(f"{mine}:one_more", 1, client=a)
    assert params.held_by(a) == (share, 8 * share)
    params.set(f"{mine}:p0", 7, client=a)  # a change of its own costs no room
    params.set(f"{theirs}:p", 1, client=b)  # the others go on
    params.set("/robot:by_the_program", 1)  # and in-process code is charged to nobody
    assert params.held_by(b) == (1, 8)
    params.set("/robot:a0", 2, client=b)  # whoever sets it next is charged for it
    assert params.held_by(a) == (share - 1, 8 * (share - 1))
    assert params.held_by(b) == (2, 16)
    params.delete(f"{mine}:p1")  # a deletion ends the charge, whoever deletes
    assert params.held_by(a) == (share - 2, 8 * (share - 2))


def test_the_share_counts_bytes_too() -> None:
    graph = small_graph()
    client = "ws:a#1"
    node = graph.nodes.attach(client)
    limit = graph.params.max_client_bytes  # 800
    graph.params.set(f"{node}:text", "x" * limit, client=client)
    with pytest.raises(ParameterStoreFullError, match=r"its share .*\(800 bytes\)"):
        graph.params.set(f"{node}:more", "y", client=client)
    graph.params.set(f"{node}:text", "short", client=client)  # shrinking frees the room
    graph.params.set(f"{node}:more", "y", client=client)


def test_a_client_creates_parameters_on_its_own_node_or_the_programs_only() -> None:
    graph = small_graph()
    params = graph.params
    for name in SERVER_NODES:  # the server's nodes, made by in-process code as the server does
        graph.create_publisher(f"{name}/out", "std_msgs/msg/String", node=name)
    params.declare("/rosapi", {"declared": 1})
    a, b = "ws:a#1", "ws:b#2"
    mine, theirs = graph.nodes.attach(a), graph.nodes.attach(b)
    for node in sorted(SERVER_NODES):
        with pytest.raises(ParameterError, match=f"node {node} is the server's"):
            params.set(f"{node}:p", 1, client=a)
    with pytest.raises(ParameterError, match=f"node {theirs} is another client's"):
        params.set(f"{theirs}:p", 1, client=a)
    with pytest.raises(ParameterError, match="node /ghost does not exist"):
        params.set("/ghost:p", 1, client=a)
    params.set(f"{mine}:p", 1, client=a)
    params.set("/robot:p", 1, client=a)
    params.set("/rosapi:declared", 2, client=a)  # changing one that exists is no creation
    params.set(f"{mine}:p", 2, client=b)  # nor on another client's node
    assert params.names() == sorted([f"{mine}:p", "/robot:p", "/rosapi:declared"])
    params.set("/ghost:p", 1)  # in-process code names any node it likes
    params.set("/rosapi:mine", 1)


def test_a_client_that_leaves_takes_its_node_and_leaves_the_rest_within_one_share() -> None:
    graph = small_graph()
    params = graph.params
    seen: list[tuple[str, object]] = []
    params.watch(lambda name, value: seen.append((name, value)))
    clients = [f"ws:c{n}#{n}" for n in range(3)]
    nodes = [graph.nodes.attach(client) for client in clients]
    for client, node in zip(clients, nodes, strict=True):
        params.set(f"{node}:own", 1, client=client)
        for n in range(5):
            params.set(f"/robot:{client[3:5]}_{n}", n, client=client)
    graph.port.release(clients[0])
    # its own node went with it; what it set on the robot stays, charged to no client
    assert not params.has(f"{nodes[0]}:own") and (f"{nodes[0]}:own", None) in seen
    assert params.has("/robot:c0_4") and params.held_by(clients[0]) == (0, 0)
    assert params.held_by(clients[1]) == (6, 48)
    graph.port.release(clients[1])
    # left behind together: 10 past a share of 8, so the oldest two go
    robot = [name for name in params.names() if name.startswith("/robot:c")]
    assert robot == [f"/robot:c0_{n}" for n in range(2, 5)] + [
        f"/robot:c1_{n}" for n in range(5)
    ] + [f"/robot:c2_{n}" for n in range(5)]
    assert ("/robot:c0_0", None) in seen and ("/robot:c0_1", None) in seen
    params.set("/robot:c0_2", 9, client=clients[2])  # a live client takes a left-over over
    assert params.held_by(clients[2]) == (7, 56)


def test_ros1_leaves_are_charged_to_the_client_that_set_them() -> None:
    graph = small_graph(Dialect.ROS1)
    params = graph.params
    client = "ws:a#1"
    graph.nodes.attach(client)
    params.set("/ui/config", {"a": 1, "b": {"c": 2, "d": [1, 2]}}, client=client)
    assert params.held_by(client)[0] == 3  # /ui/config/a, /ui/config/b/c, /ui/config/b/d
    with pytest.raises(ParameterStoreFullError, match="its share"):
        params.set("/ui/more", {f"k{n}": n for n in range(6)}, client=client)
    params.set("/ui/config/b", 5, client=client)  # a namespace replaced by a leaf
    assert params.held_by(client)[0] == 2
    graph.port.release(client)
    assert params.get("/ui/config") == {"a": 1, "b": 5}  # ROS 1 parameters outlive clients
    assert params.held_by(client) == (0, 0)


def test_an_atomic_set_by_a_client_is_judged_and_charged_as_its_sets() -> None:
    """``set_parameters_atomically`` from a rosbridge client (rwt_graph.rosapi.nodeparams)."""
    graph = small_graph()
    params = graph.params
    client = "ws:a#1"
    graph.nodes.attach(client)
    share = params.max_client_params
    params.set_all([(f"/robot:p{n}", n) for n in range(share)], client=client)
    assert params.held_by(client) == (share, 8 * share)
    with pytest.raises(ParameterStoreFullError, match="this client holds its share"):
        params.set_all([("/robot:p0", 5), ("/robot:one_more", 1)], client=client)
    assert params.get("/robot:p0") == 0 and not params.has("/robot:one_more")  # none of them
    with pytest.raises(ParameterError, match="node /ghost does not exist"):
        params.set_all([("/ghost:x", 1)], client=client)
    params.set_all([("/robot:p0", None), ("/robot:p1", 9)], client=client)  # frees one
    assert params.held_by(client) == (share - 1, 8 * (share - 1))
