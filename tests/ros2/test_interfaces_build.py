"""A package rclpy lacks is built on first use; a build that cannot run says why and what to do.

``rwt serve --ros2`` with only the pip extra has no ``tf2_msgs`` for rclpy, and builds
it the first time the link needs it (``rwt_ros2.ondemand``, docs/ros2.md): test_tf.py
has a server load the build from the cache and carry /tf. Here the build cannot run (no
compiler on the ``PATH``, an empty cache): the log says so with the fix, and a client
that subscribes to /tf is told why its messages do not cross, while the link goes on.
A build that runs past its time, or when the link stops, is stopped with every process
it started; while it runs, a client is told it is coming. (The build itself, 30-60 s of
compiling, runs in CI before the suite and in test_tf.py's fixture when not cached.)
"""

from __future__ import annotations

import importlib.util
import logging
from pathlib import Path

import pytest

from rwt_graph.graph import Graph
from rwt_graph.tf.loop import install_tf_republisher
from rwt_protocol.levels import StatusLevel
from rwt_ros2 import Ros2Options, interfaces, open_ros2_link
from tests.conftest import Peer

from .support import skip_without_rclpy, until

pytestmark = [
    pytest.mark.anyio,
    skip_without_rclpy(),
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
]

HAS_TF2_MSGS = importlib.util.find_spec("tf2_msgs") is not None


def build_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if "event=ros2_build" in r.getMessage()]


@pytest.mark.skipif(HAS_TF2_MSGS, reason="tf2_msgs is installed for rclpy")
async def test_a_build_that_cannot_run_is_logged_and_told_with_why_and_what_to_do(
    ros_env: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    (tmp_path / "bin").mkdir()
    monkeypatch.setenv("PATH", str(tmp_path / "bin"))  # no cc, c++ or make
    monkeypatch.setenv("RWT_ROS2_BUILD_DIR", str(tmp_path / "cache"))  # nothing built yet
    caplog.set_level(logging.INFO, "rwt.ros2")
    graph = Graph()
    install_tf_republisher(graph)  # its /tf and /tf_static subscriptions, as rwt serve's
    async with open_ros2_link(graph, Ros2Options(node_name="build_test")):
        await until(lambda: "state=failed" in caplog.text, "the build's failure in the log")
        web = Peer(graph, "web", StatusLevel.WARNING)
        web.send(op="subscribe", topic="/tf", type="tf2_msgs/msg/TFMessage", id="tf")
        [status] = web.statuses()
        web.send(op="subscribe", topic="/chatter", type="std_msgs/msg/String", id="chatter")
        assert web.statuses() == []  # a type rclpy has goes on as ever
        await until(lambda: "event=ros2_type_missing" in caplog.text, "the type missing logged")
    building, failed = build_lines(caplog)
    assert "package=tf2_msgs state=building" in building
    assert "reason='missing cc, c++, make (apt-get install build-essential)'" in failed
    assert "python -m rwt_ros2.build tf2_msgs" in failed  # what to do
    assert status["level"] == "warning" and status["id"] == "tf"
    message = str(status["msg"])
    assert message.startswith("subscribe: ROS 2 has no Python package for tf2_msgs/msg/TFMessage")
    assert "building it for rclpy failed: missing cc, c++, make" in message
    assert "does not cross to ROS 2" in message


def running_in(folder: Path) -> list[str]:
    """The command lines of the processes that name ``folder`` (the build's steps)."""
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            text = cmdline.read_bytes().replace(b"\0", b" ").decode("utf-8", "replace")
        except OSError:  # it ended meanwhile
            continue
        if str(folder) in text:
            found.append(text)
    return found


@pytest.mark.skipif(HAS_TF2_MSGS, reason="tf2_msgs is installed for rclpy")
async def test_a_build_past_its_time_is_stopped_with_every_process_it_started(
    ros_env: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    if missing := interfaces.missing_tools():
        pytest.skip(f"the build cannot start here: missing {', '.join(missing)}")
    cache = tmp_path / "cache"
    monkeypatch.setenv("RWT_ROS2_BUILD_DIR", str(cache))  # nothing built yet: it starts
    caplog.set_level(logging.INFO, "rwt.ros2")
    graph = Graph()
    install_tf_republisher(graph)
    options = Ros2Options(node_name="build_timeout_test", build_timeout_s=1.0)
    async with open_ros2_link(graph, options):
        await until(lambda: "state=failed" in caplog.text, "the build stopped")
        # pip, cmake or the compiler: none runs on (SIGKILL is not seen at once in /proc)
        await until(lambda: running_in(cache) == [], "every process of the build gone")
    building, failed = build_lines(caplog)
    assert "state=building" in building and "limit_s=1" in building
    assert "reason='stopped: it ran past 1 s (Ros2Options.build_timeout_s)'" in failed
    assert not interfaces.is_built(interfaces.prefix("tf2_msgs"))


@pytest.mark.skipif(HAS_TF2_MSGS, reason="tf2_msgs is installed for rclpy")
async def test_while_it_builds_clients_are_told_and_a_stopping_server_stops_the_build(
    ros_env: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    if missing := interfaces.missing_tools():
        pytest.skip(f"the build cannot start here: missing {', '.join(missing)}")
    cache = tmp_path / "cache"
    monkeypatch.setenv("RWT_ROS2_BUILD_DIR", str(cache))
    caplog.set_level(logging.INFO, "rwt.ros2")
    graph = Graph()
    install_tf_republisher(graph)
    async with open_ros2_link(graph, Ros2Options(node_name="build_stop_test")):
        await until(lambda: running_in(cache) != [], "the build running")
        web = Peer(graph, "web", StatusLevel.WARNING)
        web.send(op="subscribe", topic="/tf", type="tf2_msgs/msg/TFMessage", id="tf")
        [status] = web.statuses()
    # the link stopped: its build with it
    await until(lambda: running_in(cache) == [], "every process of the build gone")
    message = str(status["msg"])
    assert "rwt is building it for rclpy (first use, up to 600 s, then cached)" in message
    assert "it crosses to ROS 2 once built" in message
