"""Foxglove clients on `rwt serve --ros2` with real rclpy nodes.

A talker's topic reaches a FoxgloveClient (@foxglove/ws-protocol in Node) with
the talker's own CDR, byte for byte: its alignment padding byte is 0xAB, which
a fresh serialization writes as 0, so a payload that keeps it was passed on as
the link received it. An rclpy node's service answers a FoxgloveClient's call in
CDR; an rclpy node's parameters are read and set from it by foxglove_bridge's
names (``/node.param``), a byte array in base64 both ways, and changes the node
makes itself are pushed to it. A FoxgloveClient's publish reaches an rclpy
subscriber. A transient-local topic's message, published before the client
came, reaches it on subscribing.
The connection graph names rclpy nodes by their own names.
"""

from __future__ import annotations

import json
import struct
import subprocess
from pathlib import Path

import pytest
from websockets.sync.client import connect

from rwt_graph.types import Dialect, TypeRegistry
from tests.foxglove import extras
from tests.integration.client_harness import JS_DIR, ServerProcess

from .support import Peer, peers, serve_ros2, skip_without_rclpy

pytestmark = [skip_without_rclpy(), pytest.mark.node]

POINT = "geometry_msgs/msg/PointStamped"
PADDING = 4 + 15  # CDR header, then sec, nanosec, length 3, "ab\0"


@pytest.fixture(autouse=True)
def _node() -> None:
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)


def expected_cdr() -> bytes:
    """What the peer's point_raw mode publishes."""
    registry = TypeRegistry(Dialect.ROS2)
    mtype = registry.message(POINT)
    values = {
        "header": {"stamp": {"sec": 7, "nanosec": 0}, "frame_id": "ab"},
        "point": {"x": 1.0, "y": -2.0, "z": 0.5},
    }
    data = bytearray(registry.serialize(mtype, mtype.from_python(values)))
    data[PADDING] = 0xAB
    return bytes(data)


def test_a_talkers_cdr_reaches_a_foxglove_client_as_it_was_sent(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("point_raw", "/fg_point", ros_env):
        got = extras.run("receive", server.url, "/fg_point", "3")
    assert got["encoding"] == "cdr" and got["schemaName"] == POINT
    assert [bytes.fromhex(p["hex"]) for p in got["payloads"]] == [expected_cdr()] * 3
    assert got["decoded"]["header"]["frame_id"] == "ab"
    assert got["decoded"]["point"] == {"x": 1.0, "y": -2.0, "z": 0.5}


def test_a_latched_rclpy_topic_gives_a_new_foxglove_subscriber_its_message(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("latched", "/fg_ros_latched", ros_env):  # published once, before anyone asks
        got = extras.run("receive", server.url, "/fg_ros_latched", "1")
    assert got["schemaName"] == "std_msgs/msg/String"
    assert got["decoded"] == {"data": "latched"}


def test_a_foxglove_clients_publish_reaches_an_rclpy_subscriber(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("listen", "/fg_to_ros", ros_env) as listener:
        publisher = subprocess.Popen(
            extras.command("publish", server.url, "/fg_to_ros", "from foxglove"),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            cwd=JS_DIR,
        )
        try:
            heard = listener.next()
        finally:
            publisher.kill()
            publisher.communicate(timeout=10)
    assert heard == {"heard": "from foxglove"}


def test_an_rclpy_service_answers_a_foxglove_clients_call(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("serve", "/fg_ros_switch", ros_env):
        got = extras.run("call", server.url, "/fg_ros_switch", json.dumps({"data": True}))
    assert got["type"] == "std_srvs/srv/SetBool"
    assert got["schemas"] == ["std_srvs/srv/SetBool_Request", "std_srvs/srv/SetBool_Response"]
    assert (got["callId"], got["encoding"], got["failure"]) == (1, "cdr", None)
    assert got["response"] == {"success": True, "message": "ros2 got True"}


def test_an_rclpy_nodes_byte_array_is_read_and_set_from_a_foxglove_client_in_base64(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("byte_params", "fg_keys", ros_env) as node:
        assert node.next() == {"key": "0001ff"}
        got = extras.run("param", server.url, "/fg_keys.key", "byte_array", '"3q2+7w=="')
        read_back = node.next()  # the node's own get_parameter
    assert got["read"] == {"name": "/fg_keys.key", "value": "AAH/", "type": "byte_array"}
    key = {"name": "/fg_keys.key", "value": "3q2+7w==", "type": "byte_array"}
    assert got["set"] == [key] and got["pushed"] == [key]
    assert got["statuses"] == []
    assert read_back == {"key": "deadbeef"}


def test_an_rclpy_nodes_parameters_are_read_and_set_from_a_foxglove_client(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("params", "fg_robot", ros_env) as node:
        got = extras.run("params", server.url, "/fg_robot", "3.25")
        changed = node.next()
    assert {"parameters", "parametersSubscribe"} <= set(got["capabilities"])
    assert got["read"] == [
        {"name": "/fg_robot.speed", "value": 1.5, "type": "float64"},
        {"name": "/fg_robot.mode", "value": "auto"},
    ]
    speed = {"name": "/fg_robot.speed", "value": 3.25, "type": "float64"}
    assert got["set"] == [speed] and got["pushed"] == [speed]
    assert got["statuses"] == []
    assert changed == {"speed": 3.25}  # the node's own set-parameters callback saw it


def test_parameter_changes_an_rclpy_node_makes_are_pushed_to_a_foxglove_client(
    server: ServerProcess, ros_env: Path
) -> None:
    # the node sets its p00000 to 3, 4, 5... every 50 ms
    with Peer("many_params", "fg_counter", ros_env, "3"):
        got = extras.run("watch", server.url, "/fg_counter.p00000", "3")
    assert got["statuses"] == []
    first = got["first"]
    assert first["name"] == "/fg_counter.p00000" and first["value"] >= 3
    values = [each["value"] for each in got["pushed"]]
    assert all(isinstance(value, int) for value in values), got["pushed"]
    assert values == sorted(set(values)) and values[0] > first["value"], values


def test_the_connection_graph_names_rclpy_nodes(server: ServerProcess, ros_env: Path) -> None:
    with peers(ros_env, ("talk", "/fg_ros_graph"), ("listen", "/fg_ros_graph")):
        got = extras.run("graph", server.url, "/fg_ros_graph")
    assert got == {"publisherIds": ["/peer_talk"], "subscriberIds": ["/peer_listen"]}


def test_with_use_sim_time_a_simulators_clock_is_foxglove_server_time(ros_env: Path) -> None:
    server = serve_ros2(ros_env, "--use-sim-time")
    try:
        with (
            Peer("clock", "/clock", ros_env),
            connect(server.url, subprotocols=["foxglove.sdk.v1"]) as ws,
        ):
            assert "time" in json.loads(ws.recv(timeout=20))["capabilities"]
            times: list[int] = []
            while len(times) < 3:
                frame = ws.recv(timeout=20)
                if isinstance(frame, bytes) and frame[0] == 2:  # a time frame
                    times.append(struct.unpack_from("<Q", frame, 1)[0])
    finally:
        server.stop()
    # the rclpy node's sim time (from 1000 s), not the wall clock, in order
    assert all(1000 * 10**9 <= t < 2000 * 10**9 for t in times), times
    assert times == sorted(times) and len(set(times)) == 3
