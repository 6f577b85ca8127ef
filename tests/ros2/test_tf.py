"""The TF republisher (docs/tf.md) on a real ROS 2 ``/tf`` and ``/tf_static``.

Real rclpy nodes, each in its own process, broadcast as tf2 does: ``/tf_static``
transient local (published before ``rwt serve --ros2`` even starts) and ``/tf``
volatile. The TF clients of roslibpy (``/republish_tfs``) and roslib in Node
(``ROS2TFClient``: the action; ``TFClient``: actionlib topics, as ros3djs) ask for
frames in two fixed frames. rclpy carries ``tf2_msgs/msg/TFMessage`` only with its
generated package, which PyPI lacks for Kilted: ``rwt serve --ros2`` builds it on first
use (``rwt_ros2.interfaces``, then cached) and loads it into its own process. The module
builds it first (once, as CI does before the suite: the peers need it too), skips where
it cannot (no C compiler), and starts the server as a pip install runs it: nothing in its
environment points at the build.
"""

from __future__ import annotations

import importlib.util
import itertools
import json
import math
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

import anyio
import anyio.to_thread
import pytest

from rwt_ros2 import interfaces
from tests.integration.client_harness import ServerProcess, node_missing_reason
from tests.support.realclients import run_node, run_python

from .support import Peer, roslibpy_prelude, skip_without_rclpy

if TYPE_CHECKING:
    from collections.abc import Iterator

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

#: The /tf peer's base_link turns 90 degrees about z (tests/ros2/peer.py, mode tf).
QUARTER = {"x": 0.0, "y": 0.0, "z": math.sqrt(0.5), "w": math.sqrt(0.5)}
STILL = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


def _installed_for_rclpy() -> bool:
    """Whether a generated tf2_msgs is importable already (a sourced ROS 2 install)."""
    spec = importlib.util.find_spec("tf2_msgs")
    places = spec.submodule_search_locations if spec is not None else None
    return any(next(Path(p).glob("*rosidl_typesupport_c*"), None) for p in places or [])


@pytest.fixture(scope="module")
def tf_env(ros_env: Path) -> Iterator[Path]:
    """The module's ROS 2 environment, with tf2_msgs importable by its peers."""
    if _installed_for_rclpy():
        yield ros_env
        return
    where = interfaces.prefix("tf2_msgs")
    if not interfaces.is_built(where):
        if missing := interfaces.missing_tools():
            pytest.skip(
                f"tf2_msgs for rclpy is not on PyPI and cannot be built here (missing "
                f"{', '.join(missing)}): apt-get install build-essential, "
                f"then {interfaces.COMMAND} tf2_msgs"
            )
        try:
            interfaces.build("tf2_msgs")
        except interfaces.InterfaceBuildError as exc:
            pytest.fail(f"building tf2_msgs for rclpy failed: {exc}")
    with pytest.MonkeyPatch.context() as patch:
        for key, value in interfaces.runtime_env(where).items():
            patch.setenv(key, value)
        yield ros_env


def as_pip_installed(tmp: Path) -> ServerProcess:
    """`rwt serve --ros2` (TF republisher on) with none of the peers' paths to the build."""
    with pytest.MonkeyPatch.context() as patch:
        build = str(interfaces.prefix("tf2_msgs"))
        for key in ("PYTHONPATH", "LD_LIBRARY_PATH"):
            kept = [p for p in os.environ.get(key, "").split(os.pathsep) if p and build not in p]
            patch.setenv(key, os.pathsep.join(kept))
        return ServerProcess(tmp, ("--ros2",))


@pytest.fixture(scope="module")
def robot(tf_env: Path) -> Iterator[ServerProcess]:
    """A static broadcaster, then `rwt serve --ros2` (TF republisher on), then /tf's."""
    # /tf_static's one message is older than the server: only durability brings it
    with Peer("tf_static", "/tf_static", tf_env, "static_broadcaster"):
        server = as_pip_installed(tf_env)
        try:
            with Peer("tf", "/tf", tf_env, "broadcaster"):
                yield server
        finally:
            server.stop()


def _close(got: dict[str, float], want: dict[str, float]) -> bool:
    return all(math.isclose(got[k], want[k], abs_tol=1e-9) for k in want)


def check_static(sent: list[dict]) -> None:
    """camera in base_link: the static link alone, sent once (it never moves)."""
    [camera] = sent
    assert _close(camera["translation"], {"x": 0.1, "y": 0.0, "z": 0.3}), camera
    assert _close(camera["rotation"], STILL), camera


def check_composed(sent: list[dict]) -> None:
    """camera in odom: both links composed, sent only past the 1.5 cm threshold."""
    # the camera's 0.1 m along base_link's x is odom's y after base_link's quarter turn
    assert all(_close(t["translation"], {"y": 0.1, "z": 0.3}) for t in sent), sent
    assert all(_close(t["rotation"], QUARTER) for t in sent), sent
    xs = [t["translation"]["x"] for t in sent]
    # 1 cm steps: each value sent is at least two steps past the last
    assert len(xs) >= 3 and all(b - a > 0.015 for a, b in itertools.pairwise(xs)), xs


ROSLIBPY_CLIENTS = """
from roslibpy.tf import TFClient

got = {"camera in base_link": [], "camera in odom": [], "base_link in odom": []}
near = TFClient(ros, fixed_frame="base_link", angular_threshold=0.01, translation_threshold=0.01)
near.subscribe("camera", got["camera in base_link"].append)
far = TFClient(ros, fixed_frame="odom", angular_threshold=0.01, translation_threshold=0.015)
far.subscribe("camera", got["camera in odom"].append)
far.subscribe("/base_link", got["base_link in odom"].append)
wait_for(lambda: min(map(len, got.values())) >= 1 and len(got["camera in odom"]) >= 3)
print(json.dumps(got))
ros.terminate()
"""


async def test_roslibpy_tf_client_on_ros2_tf(robot: ServerProcess) -> None:
    out = await run_python(roslibpy_prelude(robot.port) + ROSLIBPY_CLIENTS)
    got = json.loads(out.strip().splitlines()[-1])
    check_static(got["camera in base_link"])
    check_composed(got["camera in odom"])
    base = got["base_link in odom"]  # the moving link alone
    assert all(_close(t["rotation"], QUARTER) for t in base), base
    assert all(_close(t["translation"], {"y": 0.0, "z": 0.0}) for t in base), base


ROSLIB_CLIENTS = """
import * as ROSLIB from "roslib";
const ros = new ROSLIB.Ros({ url: "ws://127.0.0.1:PORT" });
const got = {};
const options = { ros, angularThres: 0.01, rate: 10 };
function watch(name, Client, fixedFrame, transThres) {
  got[name] = [];
  new Client({ ...options, fixedFrame, transThres }).subscribe("camera", (t) => {
    got[name].push({ translation: { ...t.translation }, rotation: { ...t.rotation } });
  });
}
watch("action, in base_link", ROSLIB.ROS2TFClient, "base_link", 0.01);
watch("action, in odom", ROSLIB.ROS2TFClient, "odom", 0.015);
watch("topics, in base_link", ROSLIB.TFClient, "base_link", 0.01);
watch("topics, in odom", ROSLIB.TFClient, "odom", 0.015);
const report = (code) => { console.log(JSON.stringify(got)); process.exit(code); };
const timer = setTimeout(() => report(1), 20000);
setInterval(() => {
  if (Object.values(got).every((sent) => sent.length >= 3 || sent.length === 1)
      && got["action, in odom"].length >= 3 && got["topics, in odom"].length >= 3) {
    clearTimeout(timer);
    report(0);
  }
}, 50);
"""


@pytest.mark.node
@pytest.mark.skipif(node_missing_reason() is not None, reason=str(node_missing_reason()))
async def test_roslib_tf_clients_on_ros2_tf(robot: ServerProcess) -> None:
    out = await run_node(ROSLIB_CLIENTS.replace("PORT", str(robot.port)))
    got = json.loads(out.strip().splitlines()[-1])
    for way in ("action", "topics"):
        check_static(got[f"{way}, in base_link"])
        check_composed(got[f"{way}, in odom"])


ROSLIBPY_BROADCASTER = """
import pathlib
import roslibpy

tf = roslibpy.Topic(ros, "/tf", "tf2_msgs/msg/TFMessage")
stamp = {"sec": 1, "nanosec": 0}
pose = {"translation": {"x": 1.0, "y": 0.0, "z": 0.0}, "rotation": {"w": 1.0}}
frame = {"header": {"stamp": stamp, "frame_id": "map"}, "child_frame_id": "odom"}
# as a page does: at 20 Hz until it closes (the test says when), at most 30 s
stop, start = pathlib.Path(STOP), time.monotonic()
while not stop.exists() and time.monotonic() - start < 30:
    tf.publish(roslibpy.Message({"transforms": [{**frame, "transform": pose}]}))
    time.sleep(0.05)
ros.terminate()
"""


async def test_a_rosbridge_clients_tf_reaches_an_rclpy_node(
    robot: ServerProcess, tf_env: Path, tmp_path: Path
) -> None:
    """A web page's localization (map -> odom on /tf) reaches the robot's tf2 listener.

    The page broadcasts until the listener heard it: the link's /tf publisher, made
    when the page advertises, and the listener discover each other in their own time.
    """
    stop = tmp_path / "stop"
    page = roslibpy_prelude(robot.port) + ROSLIBPY_BROADCASTER.replace("STOP", repr(str(stop)))
    with Peer("tf_echo", "/tf", tf_env) as listener:
        async with anyio.create_task_group() as tg:
            tg.start_soon(run_python, page)
            try:
                heard: list[list[str]] = []
                deadline = time.monotonic() + 20
                while ["map", "odom"] not in heard:  # the robot's own (odom -> base_link) too
                    assert time.monotonic() < deadline, "no map -> odom reached the rclpy node"
                    heard = (await anyio.to_thread.run_sync(listener.next))["frames"]
            finally:
                stop.touch()
