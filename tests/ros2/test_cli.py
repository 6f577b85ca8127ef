"""`rwt serve --ros2` refuses to start without rclpy, saying what to install or source;
with it, it starts without warnings about its own helpers, and its hints name real wheels."""

from __future__ import annotations

import importlib.metadata
import os
import subprocess
from pathlib import Path

from rwt_ros2.runtime import KILTED_WHEELS, package_hint
from tests.integration.client_harness import ServerProcess
from tests.support.cli import RWT

from .support import skip_without_rclpy

REPO = Path(__file__).resolve().parents[2]


def test_without_rclpy_it_says_what_to_install_or_source(tmp_path: Path) -> None:
    # an rclpy whose libraries are missing, as on a machine without ROS sourced
    fake = tmp_path / "rclpy"
    fake.mkdir()
    (fake / "__init__.py").write_text(
        'raise ImportError("librcl.so: cannot open shared object file")\n', "utf-8"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(REPO / "src")])}
    result = subprocess.run(
        [*RWT, "serve", "--ros2", "--port", "0"],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 1
    assert "listening" not in result.stdout
    err = result.stderr
    assert "--ros2 needs rclpy (librcl.so: cannot open shared object file)" in err
    assert 'pip install "rwt-rosbridge[ros2]"' in err
    assert "source /opt/ros/<distro>/setup.bash" in err


def test_ros2_with_the_ros1_dialect_is_a_usage_error() -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    result = subprocess.run(
        [*RWT, "serve", "--ros2", "--dialect", "ros1"],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 2
    assert "--ros2 carries ROS 2 types" in result.stderr


@skip_without_rclpy()
def test_rwt_serve_ros2_starts_without_a_warning_about_its_own_helpers(ros_env: Path) -> None:
    # TF on (the default): its action, service and actionlib topics stay this server's own
    server = ServerProcess(ros_env, ("--ros2",))
    try:
        log_path = server.stderr_path
    finally:
        server.stop()  # the link shares what the graph has before the server listens
    missing = [
        line.split("topic=", 1)[1].split(" ", 1)[0]
        for line in log_path.read_text().splitlines()
        if "event=ros2_type_missing" in line
    ]
    # the robot's /tf is shared (the republisher serves it); it warns only without tf2_msgs
    assert set(missing) <= {"/tf"}, missing
    for line in log_path.read_text().splitlines():
        if "event=ros2_type_missing" in line:
            assert "PyPI has no wheel of it" in line and "pip install" not in line


def test_a_package_hint_names_a_pypi_wheel_only_where_one_exists() -> None:
    assert package_hint("sensor_msgs") == (
        "pip install ros-kilted-sensor-msgs, or apt install ros-<distro>-sensor-msgs"
    )
    hint = package_hint("tf2_msgs")
    assert "pip install" not in hint and "apt install ros-<distro>-tf2-msgs" in hint
    # the wheels installed here (the ros2 extra) are ones the hints name
    names = (dist.name or "" for dist in importlib.metadata.distributions())
    installed = {
        name.removeprefix("ros-kilted-").replace("-", "_")
        for name in names
        if name.startswith("ros-kilted-") and name.endswith(("-msgs", "-srvs", "-interfaces"))
    }
    assert {"std_msgs", "std_srvs", "rcl_interfaces"} <= installed <= KILTED_WHEELS
