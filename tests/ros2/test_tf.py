"""The TF republisher (docs/tf.md) on a real ROS 2 ``/tf`` and ``/tf_static``.

Real rclpy nodes, each in its own process, broadcast as tf2 does: ``/tf_static``
transient local (published before ``rwt serve --ros2`` even starts) and ``/tf``
volatile. roslibpy's ``TFClient`` (``/republish_tfs``) asks for frames in two fixed
frames. rclpy carries ``tf2_msgs/msg/TFMessage`` only with its generated package,
which PyPI lacks for Kilted: the module builds it first (tf2_msgs_build, once, then
cached) and skips where it cannot (no C compiler).
"""

from __future__ import annotations

import importlib.util
import itertools
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from tests.integration.client_harness import ServerProcess
from tests.transports.realclients import run_python

from . import tf2_msgs_build
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
    """The module's ROS 2 environment, with tf2_msgs importable by its processes."""
    if _installed_for_rclpy():
        yield ros_env
        return
    where = tf2_msgs_build.prefix()
    if not tf2_msgs_build.is_built(where):
        if missing := tf2_msgs_build.missing_tools():
            pytest.skip(
                f"tf2_msgs for rclpy is not on PyPI and cannot be built here (missing "
                f"{', '.join(missing)}): apt-get install build-essential, "
                f"then {tf2_msgs_build.COMMAND}"
            )
        try:
            tf2_msgs_build.build()
        except tf2_msgs_build.BuildError as exc:
            pytest.fail(f"building tf2_msgs for rclpy failed: {exc}")
    with pytest.MonkeyPatch.context() as patch:
        for key, value in tf2_msgs_build.runtime_env(where).items():
            patch.setenv(key, value)
        yield ros_env


TF_CLIENTS = """
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


def _close(got: dict[str, float], want: dict[str, float]) -> bool:
    return all(math.isclose(got[k], want[k], abs_tol=1e-9) for k in want)


async def test_ros2_tf_and_tf_static_reach_a_roslibpy_tf_client(tf_env: Path) -> None:
    # /tf_static's one message is older than the server: only durability brings it
    with Peer("tf_static", "/tf_static", tf_env, "static_broadcaster"):
        server = ServerProcess(tf_env, ("--ros2",))  # the TF republisher on
        try:
            with Peer("tf", "/tf", tf_env, "broadcaster"):
                out = await run_python(roslibpy_prelude(server.port) + TF_CLIENTS)
        finally:
            server.stop()
    got = json.loads(out.strip().splitlines()[-1])

    # the static link alone, sent once: it never moves
    [camera] = got["camera in base_link"]
    assert _close(camera["translation"], {"x": 0.1, "y": 0.0, "z": 0.3}), camera
    assert _close(camera["rotation"], STILL), camera

    # the moving link: base_link slides along x, turned a quarter about z
    base = got["base_link in odom"]
    assert all(_close(t["rotation"], QUARTER) for t in base), base
    assert all(_close(t["translation"], {"y": 0.0, "z": 0.0}) for t in base), base

    # both links composed: the camera's 0.1 m along base_link's x is odom's y after the turn
    seen = got["camera in odom"]
    assert all(_close(t["translation"], {"y": 0.1, "z": 0.3}) for t in seen), seen
    assert all(_close(t["rotation"], QUARTER) for t in seen), seen
    xs = [t["translation"]["x"] for t in seen]
    # 1 cm steps: each value sent is at least two steps past the last (threshold 1.5 cm)
    assert all(b - a > 0.015 for a, b in itertools.pairwise(xs)), xs
