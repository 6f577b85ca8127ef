"""Each node's ROS 2 parameter services, called by rosbridge clients (docs/ros2.md).

ROS 2 tools read a node's parameters from ``<node>/list_parameters`` and
``<node>/get_parameters`` (ros-mcp's ``get_parameters``, ``ros2 param list``),
not rosapi; the graph answers them from its parameter store for every node that
has parameters, under the same access rules and client shares as rosapi (D34).
"""

from __future__ import annotations

import base64

import pytest

from rwt_graph.graph import Graph
from rwt_graph.parameters.services import MAX_ANSWER_BYTES
from rwt_graph.rosapi import install_rosapi
from rwt_graph.visibility import Visibility
from rwt_protocol.runtime.access import AccessPolicy
from tests.conftest import Peer
from tests.session.rosapi_support import call, call_raw, connect

DOUBLE, STRING = 3, 4  # rcl_interfaces/msg/ParameterType


@pytest.fixture
def robot(graph: Graph) -> Graph:
    install_rosapi(graph)
    graph.params.declare("/robot", {"max_speed": 1.5, "name": "r2"})
    graph.params.declare("/robot", {"model": "turtle"}, read_only=True)
    return graph


@pytest.fixture
def web(robot: Graph) -> Peer:
    return connect(robot, "web")


def _double(value: float) -> dict[str, object]:
    return {"type": DOUBLE, "double_value": value}


def test_a_node_with_parameters_lists_and_reads_them(web: Peer) -> None:
    listed = call(web, "/robot/list_parameters")
    assert listed == {"result": {"names": ["max_speed", "model", "name"], "prefixes": []}}
    values = call(web, "/robot/get_parameters", names=["max_speed", "model", "nope"])["values"]
    assert [(v["type"], v["double_value"], v["string_value"]) for v in values] == [
        (DOUBLE, 1.5, ""),
        (STRING, 0.0, "turtle"),
        (0, 0.0, ""),  # not set
    ]
    types = call(web, "/robot/get_parameter_types", names=["name"])["types"]
    assert base64.b64decode(types) == bytes([STRING])  # uint8[]: base64, as rosbridge sends it
    [described] = call(web, "/robot/describe_parameters", names=["model"])["descriptors"]
    assert (described["name"], described["type"], described["read_only"]) == (
        "model",
        STRING,
        True,
    )


def test_set_parameters_changes_the_store_and_refuses_a_read_only_one(
    robot: Graph, web: Peer
) -> None:
    params = [
        {"name": "max_speed", "value": _double(2.5)},
        {"name": "model", "value": {"type": STRING, "string_value": "x"}},
    ]
    results = call(web, "/robot/set_parameters", parameters=params)["results"]
    assert results[0] == {"successful": True, "reason": ""}
    assert results[1]["successful"] is False and "read-only" in results[1]["reason"]
    assert robot.params.get("/robot:max_speed") == 2.5
    assert robot.params.get("/robot:model") == "turtle"


def test_what_a_client_sets_is_charged_to_it(robot: Graph, web: Peer) -> None:
    new = [{"name": "lights", "value": _double(1.0)}]
    assert call(web, "/robot/set_parameters", parameters=new)["results"][0]["successful"]
    assert robot.params.held_by("web") == (1, 8)
    atomic = [{"name": "horn", "value": _double(2.0)}]
    assert call(web, "/robot/set_parameters_atomically", parameters=atomic) == {
        "result": {"successful": True, "reason": ""}
    }
    assert robot.params.held_by("web") == (2, 16)


def test_services_come_with_the_first_parameter_and_go_with_the_last(
    robot: Graph, web: Peer
) -> None:
    robot.nodes.attach("arm_client")
    robot.params.set("/arm:joint", 1)
    services = call(web, "/rosapi/services")["services"]
    assert "/arm/list_parameters" in services
    # deleting the last one through the services themselves is answered, then they go
    gone = [{"name": "joint", "value": {"type": 0}}]  # NOT_SET deletes
    assert call(web, "/arm/set_parameters", parameters=gone) == {
        "results": [{"successful": True, "reason": ""}]
    }
    assert not robot.params.has("/arm:joint")
    assert "/arm/list_parameters" not in call(web, "/rosapi/services")["services"]
    reply = call_raw(web, "/arm/list_parameters")
    assert reply["result"] is False


def test_client_nodes_offer_no_parameter_services(robot: Graph, web: Peer) -> None:
    node = robot.nodes.node_of("web")
    assert node is not None and node.startswith("/rwt_client_")
    assert call(web, "/rosapi/set_param", name=f"{node}:x", value="1")["successful"]
    assert f"{node}/list_parameters" not in call(web, "/rosapi/services")["services"]


def test_hidden_parameters_read_as_not_set_and_cannot_be_set(graph: Graph) -> None:
    policy = AccessPolicy(params=("/robot:max_*",))
    install_rosapi(graph, visibility=lambda caller: Visibility.of(policy))
    graph.params.declare("/robot", {"max_speed": 1.5, "name": "r2"})
    web = connect(graph, "web")
    assert call(web, "/robot/list_parameters")["result"]["names"] == ["max_speed"]
    [value] = call(web, "/robot/get_parameters", names=["name"])["values"]
    assert value["type"] == 0
    params = [{"name": "name", "value": {"type": STRING, "string_value": "evil"}}]
    [result] = call(web, "/robot/set_parameters", parameters=params)["results"]
    assert result["successful"] is False and "not accessible" in result["reason"]
    assert graph.params.get("/robot:name") == "r2"


def test_an_answer_over_the_bound_is_refused(robot: Graph, web: Peer) -> None:
    robot.params.set("/robot:blob", "x" * (1024 * 1024))
    names = ["blob"] * (MAX_ANSWER_BYTES // (1024 * 1024) + 1)
    reply = call_raw(web, "/robot/get_parameters", names=names)
    assert reply["result"] is False
    assert f"more than {MAX_ANSWER_BYTES} bytes" in str(reply["values"])
    # the server still answers others
    assert call(connect(robot, "other"), "/robot/get_parameter_types", names=["name"])
