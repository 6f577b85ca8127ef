"""rosapi in the ROS 1 dialect: its types, parameters and extra services (REF §7.1)."""

from __future__ import annotations

import json
import platform

import pytest

from rwt_graph.graph import Graph
from rwt_graph.rosapi import install_rosapi
from rwt_graph.types import Dialect, TypeRegistry
from tests.conftest import FakeClock, Peer
from tests.session.rosapi_support import call, call_raw, connect


@pytest.fixture
def ros1(clock: FakeClock) -> Graph:
    graph = Graph(TypeRegistry(Dialect.ROS1), clock=clock)
    install_rosapi(graph)
    graph.params.set("/robot", {"max_speed": 1.5, "arm": {"joints": 6}})
    return graph


@pytest.fixture
def web(ros1: Graph) -> Peer:
    return connect(ros1, "web", host="10.0.0.7")


def test_types_are_pkg_slash_type(ros1: Graph, web: Peer) -> None:
    web.send(op="advertise", topic="/chatter", type="std_msgs/msg/String")
    assert call(web, "/rosapi/topics") == {"topics": ["/chatter"], "types": ["std_msgs/String"]}
    assert call(web, "/rosapi/service_type", service="/rosapi/topics") == {"type": "rosapi/Topics"}
    assert call(web, "/rosapi/topics_for_type", type="std_msgs/String") == {"topics": ["/chatter"]}


def test_time_is_secs_nsecs_and_there_is_no_ros_version(web: Peer, clock: FakeClock) -> None:
    clock.epoch = 12.25
    assert call(web, "/rosapi/get_time") == {"time": {"secs": 12, "nsecs": 250_000_000}}
    reply = call_raw(web, "/rosapi/get_ros_version")
    assert reply["result"] is False
    assert "does not exist" in str(reply["values"])


def test_message_details_uses_ros1_names_and_a_made_up_time_typedef(web: Peer) -> None:
    [header, time] = call(web, "/rosapi/message_details", type="std_msgs/Header")["typedefs"]
    assert header == {
        "type": "std_msgs/Header",
        "fieldnames": ["seq", "stamp", "frame_id"],
        "fieldtypes": ["uint32", "time", "string"],
        "fieldarraylen": [-1, -1, -1],
        "examples": ["0", "{}", ""],
        "constnames": [],
        "constvalues": [],
    }
    assert time == {
        "type": "time",
        "fieldnames": ["secs", "nsecs"],
        "fieldtypes": ["int32", "int32"],
        "fieldarraylen": [-1, -1],
        "examples": ["0", "0"],
        "constnames": [],
        "constvalues": [],
    }
    [request] = call(web, "/rosapi/service_request_details", type="std_srvs/SetBool")["typedefs"]
    assert request["type"] == "std_srvs/SetBoolRequest"
    assert request["fieldtypes"] == ["bool"]


def test_params_are_global_names_with_namespaces(ros1: Graph, web: Peer) -> None:
    assert call(web, "/rosapi/get_param_names") == {
        "names": ["/robot/arm/joints", "/robot/max_speed"]
    }
    assert json.loads(call(web, "/rosapi/get_param", name="/robot")["value"]) == {
        "max_speed": 1.5,
        "arm": {"joints": 6},
    }
    assert call(web, "/rosapi/set_param", name="robot/arm/names", value='["a", 2, true]') == {}
    assert ros1.params.get("/robot/arm/names") == ("a", 2, True)
    assert call(web, "/rosapi/has_param", name="/robot/arm") == {"exists": True}
    assert call(web, "/rosapi/search_param", name="robot/max_speed") == {
        "global_name": "/robot/max_speed"
    }
    assert call(web, "/rosapi/search_param", name="nothing") == {"global_name": ""}
    assert call(web, "/rosapi/delete_param", name="/robot/arm") == {}
    assert call(web, "/rosapi/delete_param", name="/robot/arm") == {}  # nothing to delete: fine
    assert ros1.params.names() == ["/robot/max_speed"]


def test_get_param_default_field_and_missing_values(web: Peer) -> None:
    assert call(web, "/rosapi/get_param", name="/nope") == {"value": "null"}
    assert call(web, "/rosapi/get_param", name="/nope", default="5") == {"value": "5"}
    assert call(web, "/rosapi/get_param", name="/nope", default="text") == {"value": '"text"'}


@pytest.mark.parametrize(
    ("value", "reason"),
    [
        ("not json", "set_param value: invalid JSON"),
        ("null", "a ROS 1 parameter cannot be NoneType"),
    ],
)
def test_refused_set_param_fails_the_call(ros1: Graph, web: Peer, value: str, reason: str) -> None:
    reply = call_raw(web, "/rosapi/set_param", name="/p", value=value)
    assert reply["result"] is False
    assert reason in str(reply["values"])
    assert not ros1.params.has("/p")


def test_service_host_is_the_client_address_or_this_machine(ros1: Graph, web: Peer) -> None:
    web.send(op="advertise_service", service="/light", type="std_srvs/SetBool")
    assert call(web, "/rosapi/service_host", service="/light") == {"host": "10.0.0.7"}
    assert call(web, "/rosapi/service_host", service="/rosapi/nodes") == {"host": platform.node()}
    assert call(web, "/rosapi/service_host", service="/none") == {"host": ""}
    assert call(web, "/rosapi/service_node", service="/light") == {"node": "/rwt_client_1"}


def test_actionlib_topic_sets_count_as_action_servers(ros1: Graph, web: Peer) -> None:
    ns = "/tf2_web_republisher"
    web.send(op="advertise", topic=f"{ns}/goal", type="actionlib_msgs/GoalID")
    web.send(op="advertise", topic=f"{ns}/cancel", type="actionlib_msgs/GoalID")
    web.send(op="advertise", topic=f"{ns}/status", type="actionlib_msgs/GoalStatusArray")
    web.send(op="advertise", topic=f"{ns}/feedback", type="std_msgs/String")
    assert call(web, "/rosapi/action_servers") == {"action_servers": []}
    web.send(op="advertise", topic=f"{ns}/result", type="std_msgs/String")
    assert call(web, "/rosapi/action_servers") == {"action_servers": [ns]}


def test_a_namespace_past_one_answer_is_refused_with_how_to_ask(ros1: Graph, web: Peer) -> None:
    blob = "x" * (1024 * 1024)
    for n in range(5):  # 5 MiB under /maps: more than one answer carries (4 MiB)
        ros1.params.set(f"/maps/m{n}", blob)
    reply = call_raw(web, "/rosapi/get_param", name="/", default="")  # 60 bytes of request
    assert reply["result"] is False
    assert reply["values"] == (
        "service /rosapi/get_param failed: the namespace / holds more than one answer "
        "carries (4194304 bytes of JSON): get the namespaces and parameters in it by name "
        "(get_param_names lists them)"
    )
    assert len(call(web, "/rosapi/get_param_names")["names"]) == 7
    assert json.loads(call(web, "/rosapi/get_param", name="/maps/m4", default="")["value"]) == blob
    robot = call(web, "/rosapi/get_param", name="/robot", default="")  # a namespace that fits
    assert json.loads(robot["value"]) == {"max_speed": 1.5, "arm": {"joints": 6}}
