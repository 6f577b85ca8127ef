"""rosapi's parameter calls reach a real rclpy node's parameters through `rwt serve --ros2`."""

from __future__ import annotations

import json
from pathlib import Path

import anyio
import pytest

from tests.integration.client_harness import ServerProcess
from tests.transports.realclients import run_python

from .support import JsonLines, Peer, roslibpy_prelude, skip_without_rclpy

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

PARAMS = """
names = roslibpy.Service(ros, "/rosapi/get_param_names", "rosapi_msgs/srv/GetParamNames")
listed = wait_for(lambda: "/robot_params:speed" in names.call(roslibpy.ServiceRequest({}))["names"])
speed = roslibpy.Param(ros, "/robot_params:speed")
mode = roslibpy.Param(ros, "/robot_params:mode")
before = [speed.get(timeout=10), mode.get(timeout=10)]
speed.set(2.5, timeout=10)
print(json.dumps({"listed": listed, "before": before}), flush=True)
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
    assert out == {"listed": True, "before": [1.5, "auto"]}
    assert changed == {"speed": 2.5}  # the node's own set-parameters callback saw it


WEB_PARAMS = """
gain = roslibpy.Param(ros, "/rosbridge_websocket:gain")  # a node the graph has
gain.set(2.5, timeout=10)
print(json.dumps({"set": True}), flush=True)
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
            assert await lines.next() == {"set": True}
        with Peer("param_client", "/rosbridge_websocket", ros_env) as ros2:
            got = await anyio.to_thread.run_sync(ros2.next)
            put = await anyio.to_thread.run_sync(ros2.next)
        await client.stdin.send(b"\n")
        with anyio.fail_after(20):
            now = await lines.last()
    assert got == {"gain": 2.5}
    assert put == {"set": True}
    assert now == {"now": 7.0}
