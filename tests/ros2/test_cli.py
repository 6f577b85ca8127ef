"""`rwt serve --ros2` refuses to start without rclpy, saying what to install or source."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from tests.support.cli import RWT

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
    assert 'pip install "rwt[ros2]"' in err
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
