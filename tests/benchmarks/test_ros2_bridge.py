"""The ROS 2 bridge benchmark (benchmarks/ros2_bridge.py) runs tiny against ``rwt serve --ros2``."""

from __future__ import annotations

import asyncio
import os

import pytest
from benchmarks.ros2_bridge import FASTDDS, Case, rclpy_available, ros_env, run_case, table

pytestmark = pytest.mark.skipif(
    not rclpy_available(), reason='rclpy is not importable: pip install "rwt[ros2]"'
)

#: Clear of tests/ros2's domains (from 150) and of the benchmark's default (130-139).
DOMAIN = 140 + os.getpid() % 10


def test_rclpy_publisher_reaches_every_websocket_subscriber_through_rwt() -> None:
    result = asyncio.run(run_case("rwt", Case("string", 20, 2), 1.0, DOMAIN))
    assert result.sent >= 15
    assert result.delivered == 2 * result.sent  # lightly paced: nothing lost
    assert result.loss == 0
    assert 0 <= result.p50_ms <= result.p99_ms
    assert result.cpu_us_per_delivery >= 0
    assert "| String 100 B 20 Hz | 2 | rwt serve --ros2 |" in table([result])


def test_every_image_reaches_the_lean_subscribers_whole() -> None:
    """The lean client checks each image's base64 in place (benchmarks/ros2_client.py):
    a wrong delivery would fail the case."""
    result = asyncio.run(run_case("rwt", Case("image", 30, 2), 1.0, DOMAIN, fastdds="large-shm"))
    assert result.sent >= 20
    assert result.delivered == 2 * result.sent
    assert "| Image 640x480 30 Hz | 2 | rwt serve --ros2 |" in table([result])


def test_each_fastdds_setup_loads_its_own_profile_or_none() -> None:
    """``--fastdds default`` is Fast DDS out of the box: no XML profile at all."""
    assert "FASTDDS_DEFAULT_PROFILES_FILE" not in ros_env(DOMAIN, "default")
    texts = {}
    for name in ("loopback", "large-shm"):
        profile = FASTDDS[name]
        assert profile is not None
        assert ros_env(DOMAIN, name)["FASTDDS_DEFAULT_PROFILES_FILE"] == str(profile)
        texts[name] = profile.read_text()
    assert all("<type>SHM</type>" in text for text in texts.values())
    assert "<segment_size>4194304</segment_size>" in texts["large-shm"]
    assert "<segment_size>" not in texts["loopback"]
