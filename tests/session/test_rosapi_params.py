"""Parameters through rosapi, ROS 2 shapes (REF §7.1; rosapi_msgs with successful/reason).

Values travel as JSON text, as roslibjs' and roslibpy's Param send them.
"""

from __future__ import annotations

import json

import pytest

from rwt_graph.graph import Graph
from rwt_graph.rosapi import install_rosapi
from tests.conftest import Peer
from tests.session.rosapi_support import call, connect

OK = {"successful": True, "reason": ""}


@pytest.fixture
def robot(graph: Graph) -> Graph:
    install_rosapi(graph)
    graph.params.declare("/robot", {"max_speed": 1.5, "name": "r2", "gains": [1.0, 2.0]})
    graph.params.declare("/robot", {"model": "turtle"}, read_only=True)
    return graph


@pytest.fixture
def web(robot: Graph) -> Peer:
    return connect(robot, "web")


def test_get_param_names_lists_node_colon_param(web: Peer) -> None:
    assert call(web, "/rosapi/get_param_names") == {
        "names": ["/robot:gains", "/robot:max_speed", "/robot:model", "/robot:name"]
    }


@pytest.mark.parametrize(
    ("name", "value"),
    [("/robot:max_speed", 1.5), ("robot:name", "r2"), ("/robot:gains", [1.0, 2.0])],
)
def test_get_param_answers_json_text(web: Peer, name: str, value: object) -> None:
    reply = call(web, "rosapi/get_param", name=name)
    assert reply == {"value": json.dumps(value), **OK}
    assert json.loads(reply["value"]) == value


def test_set_param_is_seen_by_python_and_by_clients(robot: Graph, web: Peer) -> None:
    seen: list[tuple[str, object]] = []
    robot.params.watch(lambda name, value: seen.append((name, value)))
    assert call(web, "/rosapi/set_param", name="/robot:max_speed", value="2.5") == OK
    assert robot.params.get("/robot:max_speed") == 2.5
    assert seen == [("/robot:max_speed", 2.5)]
    other = connect(robot, "other")
    assert call(other, "/rosapi/get_param", name="/robot:max_speed")["value"] == "2.5"


def test_set_param_creates_a_parameter_on_an_existing_node(robot: Graph, web: Peer) -> None:
    assert call(web, "/rosapi/set_param", name="/robot:lights", value="[true, false]") == OK
    assert robot.params.get("/robot:lights") == (True, False)
    web.send(op="advertise", topic="/x", type="std_msgs/String")
    assert call(web, "/rosapi/set_param", name="/rwt_client_1:mine", value='"yes"') == OK
    assert robot.params.get("/rwt_client_1:mine") == "yes"
    assert "/rwt_client_1:mine" in call(web, "/rosapi/get_param_names")["names"]


def test_a_client_creates_on_its_own_node_or_the_robots_and_is_charged_for_it(
    robot: Graph, web: Peer
) -> None:
    other = connect(robot, "other")  # /rwt_client_2
    refused = {
        "/rosapi:x": "node /rosapi is the server's: no client creates parameters on it",
        "/rwt_client_2:x": "node /rwt_client_2 is another client's: a client creates "
        "parameters on its own node or on the robot's",
    }
    for name, reason in refused.items():
        reply = call(web, "/rosapi/set_param", name=name, value="1")
        assert reply == {"successful": False, "reason": reason}
    assert call(other, "/rosapi/set_param", name="/rwt_client_2:x", value="1") == OK
    assert call(web, "/rosapi/set_param", name="/rwt_client_1:x", value='"abc"') == OK
    assert call(web, "/rosapi/set_param", name="/robot:fresh", value="2") == OK
    assert call(web, "/rosapi/set_param", name="/robot:max_speed", value="2.5") == OK
    assert robot.params.held_by("web") == (3, 3 + 8 + 8)  # each value's bytes
    assert robot.params.held_by("other") == (1, 8)
    web.session.close()  # it disconnects: its node goes, what it set on the robot stays
    names = call(other, "/rosapi/get_param_names")["names"]
    assert "/rwt_client_1:x" not in names and "/robot:fresh" in names
    assert call(other, "/rosapi/get_param", name="/robot:max_speed")["value"] == "2.5"
    assert robot.params.held_by("web") == (0, 0)


@pytest.mark.parametrize(
    ("name", "value", "reason"),
    [
        ("/ghost:p", "1", "node /ghost does not exist"),
        ("/robot:max_speed", '"fast"', "parameter /robot:max_speed has type double, not string"),
        ("/robot:model", '"hare"', "parameter /robot:model is read-only"),
        ("/robot:max_speed", "fast", "set_param value: invalid JSON: Expecting value"),
        ("/robot:new", '{"a": 1}', "/robot:new: a ROS 2 parameter is a bool, int, float, str"),
        ("max_speed", "1", "parameter name 'max_speed': expected <node>:<parameter>"),
    ],
)
def test_set_param_refusals_say_why(
    robot: Graph, web: Peer, name: str, value: str, reason: str
) -> None:
    before = robot.params.names()
    reply = call(web, "/rosapi/set_param", name=name, value=value)
    assert reply["successful"] is False
    assert str(reply["reason"]).startswith(reason)
    assert robot.params.names() == before
    assert robot.params.get("/robot:max_speed") == 1.5


def test_int_for_a_double_parameter_is_widened(robot: Graph, web: Peer) -> None:
    assert call(web, "/rosapi/set_param", name="/robot:max_speed", value="3") == OK
    assert call(web, "/rosapi/get_param", name="/robot:max_speed")["value"] == "3.0"


def test_a_byte_array_reads_and_writes_as_a_list_of_octets(robot: Graph, web: Peer) -> None:
    robot.params.declare("/robot", {"key": b"\x00\x7f\xff"})
    assert call(web, "/rosapi/get_param", name="/robot:key") == {"value": "[0, 127, 255]", **OK}
    assert call(web, "/rosapi/set_param", name="/robot:key", value="[1, 2]") == OK
    assert robot.params.get("/robot:key") == b"\x01\x02"  # still a byte array
    reply = call(web, "/rosapi/set_param", name="/robot:key", value="[1, 300]")
    assert reply == {
        "successful": False,
        "reason": "parameter /robot:key has type byte_array, not integer_array",
    }


def test_get_param_of_a_missing_parameter(web: Peer) -> None:
    missing = call(web, "/rosapi/get_param", name="/robot:missing")
    assert missing == {
        "value": "null",
        "successful": False,
        "reason": "parameter /robot:missing is not set",
    }
    assert call(web, "/rosapi/get_param", name="/robot:missing", default_value="[1, 2]") == {
        "value": "[1, 2]",
        **OK,
    }
    # a default that is not JSON is taken as a string, as rosapi does
    assert call(web, "/rosapi/get_param", name="/robot:missing", default_value="abc")[
        "value"
    ] == json.dumps("abc")


def test_has_and_delete_param(robot: Graph, web: Peer) -> None:
    assert call(web, "/rosapi/has_param", name="/robot:name") == {"exists": True}
    assert call(web, "/rosapi/delete_param", name="/robot:name") == OK
    assert call(web, "/rosapi/has_param", name="/robot:name") == {"exists": False}
    assert not robot.params.has("/robot:name")
    assert call(web, "/rosapi/delete_param", name="/robot:name") == {
        "successful": False,
        "reason": "parameter /robot:name is not set",
    }
    assert call(web, "/rosapi/delete_param", name="/robot:model")["successful"] is False
    assert call(web, "/rosapi/has_param", name="no colon") == {"exists": False}


def test_non_finite_values_read_as_null(robot: Graph, web: Peer) -> None:
    robot.params.set("/robot:max_speed", float("inf"))
    assert call(web, "/rosapi/get_param", name="/robot:max_speed")["value"] == "null"


def test_nodes_with_parameters_are_nodes(web: Peer) -> None:
    assert "/robot" in call(web, "/rosapi/nodes")["nodes"]
    assert call(web, "/rosapi/node_details", node="/robot") == {
        "subscribing": [],
        "publishing": [],
        "services": [  # as a ROS 2 node: its parameter services (test_node_params)
            "/robot/describe_parameters",
            "/robot/get_parameter_types",
            "/robot/get_parameters",
            "/robot/list_parameters",
            "/robot/set_parameters",
            "/robot/set_parameters_atomically",
        ],
    }
