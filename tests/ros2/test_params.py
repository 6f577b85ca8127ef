"""rosapi's parameter calls reach a real rclpy node's parameters through `rwt serve --ros2`."""

from __future__ import annotations

import json
from pathlib import Path

import anyio
import pytest

from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .support import JsonLines, Peer, roslibpy_prelude, skip_without_rclpy

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

PARAMS = """
names = roslibpy.Service(ros, "/rosapi/get_param_names", "rosapi_msgs/srv/GetParamNames")
listed = wait_for(lambda: "/robot_params:speed" in names.call(roslibpy.ServiceRequest({}))["names"])
speed = roslibpy.Param(ros, "/robot_params:speed")
mode = roslibpy.Param(ros, "/robot_params:mode")
before = [speed.get(timeout=10), mode.get(timeout=10)]
speed.set(2.5, timeout=10)
after = speed.get(timeout=10)  # read back at once, not at the copy's next refresh
print(json.dumps({"listed": listed, "before": before, "after": after}), flush=True)
ros.terminate()
"""


async def test_rosapi_reads_and_sets_a_ros2_nodes_parameters(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("params", "robot_params", ros_env) as node:
        out = json.loads(
            (await run_python(roslibpy_prelude(server.port) + PARAMS)).splitlines()[-1]
        )
        changed = await anyio.to_thread.run_sync(node.next)
    assert out == {"listed": True, "before": [1.5, "auto"], "after": 2.5}
    assert changed == {"speed": 2.5}  # the node's own set-parameters callback saw it


WEB_PARAMS = """
node = own_node()  # where a client creates parameters (docs/decisions.md, D34)
gain = roslibpy.Param(ros, f"{node}:gain")
gain.set(2.5, timeout=10)
print(json.dumps({"set": node}), flush=True)
input()  # the ROS 2 node reads it and sets it to 7 meanwhile
print(json.dumps({"now": gain.get(timeout=10)}))
ros.terminate()
"""


async def test_a_ros2_node_reads_and_sets_parameters_a_rosbridge_client_set(
    server: ServerProcess, ros_env: Path
) -> None:
    async with await anyio.open_process(
        ["python", "-c", roslibpy_prelude(server.port) + WEB_PARAMS]
    ) as client:
        assert client.stdout is not None and client.stdin is not None
        lines = JsonLines(client.stdout)
        with anyio.fail_after(20):
            node = (await lines.next())["set"]
        with Peer("param_client", node, ros_env) as ros2:
            got = await anyio.to_thread.run_sync(ros2.next)
            put = await anyio.to_thread.run_sync(ros2.next)
        await client.stdin.send(b"\n")
        with anyio.fail_after(20):
            now = await lines.last()
    assert got == {"gain": 2.5}
    assert put == {"set": True}
    assert now == {"now": 7.0}


TUNING = """
node = own_node()
params = {n: roslibpy.Param(ros, f"{node}:{n}") for n in ("volume", "style", "spare")}
for param, value in zip(params.values(), (2.5, "auto", 1)):
    param.set(value, timeout=10)
print(json.dumps({"set": node}), flush=True)
input()  # the ROS 2 node describes them and sets them atomically meanwhile
names = roslibpy.Service(ros, "/rosapi/get_param_names", "rosapi_msgs/srv/GetParamNames")
ours = [f"{node}:{n}" for n in params]
listed = [n for n in names.call(roslibpy.ServiceRequest({}))["names"] if n in ours]
now = [params["volume"].get(timeout=10), params["style"].get(timeout=10)]
print(json.dumps({"now": now, "listed": listed}))
ros.terminate()
"""


async def test_a_ros2_node_describes_and_sets_atomically_parameters_a_rosbridge_client_set(
    server: ServerProcess, ros_env: Path
) -> None:
    async with await anyio.open_process(
        ["python", "-c", roslibpy_prelude(server.port) + TUNING]
    ) as client:
        assert client.stdout is not None and client.stdin is not None
        lines = JsonLines(client.stdout)
        with anyio.fail_after(20):
            node = (await lines.next())["set"]
        with Peer("param_suite", node, ros_env) as ros2:
            described = await anyio.to_thread.run_sync(ros2.next)
            types = await anyio.to_thread.run_sync(ros2.next)
            atomic = await anyio.to_thread.run_sync(ros2.next)
        await client.stdin.send(b"\n")
        with anyio.fail_after(20):
            now = await lines.last()
    # name and type as rclcpp fills them (rclpy leaves them empty for parameters set
    # without a declaration); a name not set: NOT_SET, as in get_parameter_types
    assert described == {
        "described": [
            ["volume", 3, False, True],
            ["style", 4, False, True],
            ["nope", 0, False, False],
        ]
    }
    assert types == {"types": [3, 4, 0]}  # DOUBLE, STRING, NOT_SET: what rclpy answers
    assert atomic == {"atomic": [[False, f"parameter {node}:nope is not set"], [True, ""]]}
    # the refused set changed nothing (style stays "auto"); the other made both changes
    assert now == {"now": [7.0, "auto"], "listed": [f"{node}:style", f"{node}:volume"]}


REFUSALS = """
set_param = roslibpy.Service(ros, "/rosapi/set_param", "rosapi_msgs/srv/SetParam")
names = roslibpy.Service(ros, "/rosapi/get_param_names", "rosapi_msgs/srv/GetParamNames")

def put(name, value):
    request = roslibpy.ServiceRequest({"name": "/guarded:" + name, "value": json.dumps(value)})
    return dict(set_param.call(request, timeout=10))

wait_for(lambda: "/guarded:limit" in names.call(roslibpy.ServiceRequest({}))["names"])
print(json.dumps({
    "type change": put("speed", "fast"),
    "read-only": put("model", "x2"),
    "validation": put("limit", -1.0),
    "accepted": put("limit", 3.0),
}), flush=True)
ros.terminate()
"""


async def test_set_param_answers_what_the_node_answered(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("guarded_params", "guarded", ros_env):
        out = await run_python(roslibpy_prelude(server.port) + REFUSALS)
        with Peer("read_params", "/guarded", ros_env) as reader:
            on_node = await anyio.to_thread.run_sync(reader.next)
    answers = json.loads(out.splitlines()[-1])
    assert answers["accepted"] == {"successful": True, "reason": ""}
    for refusal in ("type change", "read-only", "validation"):
        assert answers[refusal]["successful"] is False, refusal
    assert "limit must not be negative" in answers["validation"]["reason"]
    assert "read-only" in answers["read-only"]["reason"]
    assert "type" in answers["type change"]["reason"]
    assert on_node == {"values": {"speed": 2.5, "model": "x1", "limit": 3.0}}


BYTES = """
names = roslibpy.Service(ros, "/rosapi/get_param_names", "rosapi_msgs/srv/GetParamNames")
wait_for(lambda: "/byte_keys:key" in names.call(roslibpy.ServiceRequest({}))["names"])
key = roslibpy.Param(ros, "/byte_keys:key")
before = key.get(timeout=10)
key.set([7, 8], timeout=10)  # what it read, changed: a list of octets
print(json.dumps({"before": before, "after": key.get(timeout=10)}), flush=True)
ros.terminate()
"""


async def test_rosapi_reads_and_sets_a_ros2_byte_array_as_a_list_of_octets(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("byte_params", "byte_keys", ros_env) as node:
        assert await anyio.to_thread.run_sync(node.next) == {"key": "0001ff"}
        out = json.loads((await run_python(roslibpy_prelude(server.port) + BYTES)).splitlines()[-1])
        read_back = await anyio.to_thread.run_sync(node.next)  # the node's own get_parameter
    assert out == {"before": [0, 1, 255], "after": [7, 8]}
    assert read_back == {"key": "0708"}  # still a byte array on the node
