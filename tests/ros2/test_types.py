"""Types ROS 2 cannot carry here get a clear warning naming the package to install."""

from __future__ import annotations

import json
from pathlib import Path

import anyio
import pytest

from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .support import HERE, peers, roslibpy_prelude, serve_ros2, skip_without_rclpy

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

DATA = HERE / "data"

STATUSES = """
import json
from websockets.sync.client import connect

with connect("ws://127.0.0.1:{port}") as ws:
    ws.send(json.dumps({{"op": "set_level", "level": "warning"}}))
    ws.send(json.dumps({{"op": "subscribe", "id": "s1", "topic": "/tf",
                        "type": "tf2_msgs/msg/TFMessage"}}))
    ws.send(json.dumps({{"op": "subscribe", "id": "s2", "topic": "/fine",
                        "type": "std_msgs/msg/String"}}))
    ws.send(json.dumps({{"op": "advertise", "id": "a1", "topic": "/fine_too",
                        "type": "std_msgs/msg/String"}}))
    ws.send(json.dumps({{"op": "call_service", "id": "c1", "service": "/rosapi/get_time"}}))
    statuses = []
    while True:
        frame = json.loads(ws.recv(timeout=20))
        if frame["op"] == "service_response":
            break
        if frame["op"] == "status":
            statuses.append(frame)
print(json.dumps(statuses))
"""


async def test_a_type_without_its_python_package_gets_a_warning_naming_it(
    server: ServerProcess,
) -> None:
    out = await run_python(STATUSES.format(port=server.port))
    statuses = json.loads(out.strip().splitlines()[-1])
    assert [(s["level"], s.get("id")) for s in statuses] == [("warning", "s1")], statuses
    text = statuses[0]["msg"]
    assert text.startswith("subscribe: ROS 2 has no Python package for tf2_msgs/msg/TFMessage")
    # PyPI has no tf2_msgs wheel: the hint names none (test_cli.py checks the rule)
    assert "apt install ros-<distro>-tf2-msgs (PyPI has no wheel of it)" in text
    assert "pip install" not in text


HASHED = """
chatter, joints = [], []
roslibpy.Topic(ros, "/foreign_chatter", "std_msgs/msg/String").subscribe(chatter.append)
roslibpy.Topic(ros, "/foreign_joints", "sensor_msgs/msg/JointState").subscribe(joints.append)
wait_for(lambda: len(joints) >= 10)
print(json.dumps({"joints": len(joints) >= 10, "chatter": chatter}))
ros.terminate()
"""


async def test_a_ros2_type_of_another_definition_is_refused_and_disturbs_nothing(
    ros_env: Path,
) -> None:
    # rwt's std_msgs/String has a field the robot's has not: another RIHS01 hash
    server = serve_ros2(ros_env, "--interfaces", str(DATA))
    try:
        with peers(ros_env, ("talk", "/foreign_chatter"), ("joints", "/foreign_joints")):
            refused = "/foreign_chatter: /peer_talk's std_msgs/msg/String is RIHS01_"
            with anyio.fail_after(60):  # the talker is discovered (and refused); a busy machine
                while refused not in server.stderr_text():
                    await anyio.sleep(0.1)
            out = await run_python(roslibpy_prelude(server.port) + HASHED)
    finally:
        server.stop()
    assert json.loads(out.strip().splitlines()[-1]) == {"joints": True, "chatter": []}
    assert "give rwt the robot's definitions" in server.stderr_text()


async def test_a_type_clash_on_a_topic_keeps_the_first_type_and_warns_once(
    server: ServerProcess, ros_env: Path
) -> None:
    # the module's server: its log is read for /clash's skip lines only
    def skips() -> list[str]:
        lines = server.stderr_text().splitlines()
        return [x for x in lines if "event=ros2_skip" in x and "/clash" in x]

    with peers(ros_env, ("talk", "/clash"), ("joints", "/clash")):
        with anyio.fail_after(60):  # both are discovered (slow on a busy machine); one skipped
            while not skips():
                await anyio.sleep(0.1)
        await anyio.sleep(1)  # five more sweeps (SWEEP_S 0.2): the same episode, no new line
    skipped = skips()
    # one line per skipped endpoint and episode (which of the two is kept depends on
    # discovery order), each a warning
    assert 1 <= len(skipped) <= 2, skipped
    assert all(" WARNING rwt." in line for line in skipped), skipped
