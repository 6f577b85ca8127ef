"""/rosout through `rwt serve --ros2`: ROS 2 nodes' log lines and rwt's own reach clients."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .support import Peer, roslibpy_prelude, skip_without_rclpy

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

ROSOUT = """
logs = []
roslibpy.Topic(ros, "/rosout", "rcl_interfaces/msg/Log").subscribe(logs.append)
def found():
    ours = [m for m in logs if m["name"] == "rwt" and "event=connect" in m["msg"]]
    theirs = [m for m in logs if m["name"] == "peer_log" and m["msg"] == "hello from ros2"]
    return ours and theirs and (ours[0], theirs[0])
wait_for(found)
print(json.dumps(found() or [m["name"] + ": " + m["msg"] for m in logs[:20]]))
ros.terminate()
"""


async def test_rosout_carries_ros2_logs_and_rwts_own(server: ServerProcess, ros_env: Path) -> None:
    with Peer("log", "hello from ros2", ros_env):
        out = await run_python(roslibpy_prelude(server.port) + ROSOUT)
    ours, theirs = json.loads(out.strip().splitlines()[-1])
    assert ours["level"] == 20  # INFO
    assert "rwt.server: event=connect" in ours["msg"]
    assert theirs["level"] == 20
