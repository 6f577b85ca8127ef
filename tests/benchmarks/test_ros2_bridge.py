"""The ROS 2 bridge benchmark (benchmarks/ros2_bridge.py) runs tiny against ``rwt serve --ros2``."""

from __future__ import annotations

import asyncio
import os

import pytest
from benchmarks.ros2_bridge import Case, rclpy_available, run_case, table

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
