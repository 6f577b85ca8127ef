"""The graph-change benchmark (benchmarks/ros2_graph.py) runs tiny against rwt."""

from __future__ import annotations

import os

import pytest
from benchmarks.ros2_bridge import rclpy_available
from benchmarks.ros2_graph import run, table

#: Clear of tests/ros2's domains (from 150), test_ros2_foxglove.py's (100-109),
#: test_ros2_bridge.py's (140-149) and the benchmarks' defaults (120, 130-139).
DOMAIN = 110 + os.getpid() % 10


@pytest.mark.skipif(
    not rclpy_available(), reason='rclpy is not importable: pip install "rwt-rosbridge[ros2]"'
)
# rclpy's generated packages import a deprecated module when first loaded here
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_rosapi_and_the_middleware_both_list_every_topic_of_each_new_node() -> None:
    rounds = run(1, 5, DOMAIN)  # raises when a side misses a topic for ROUND_LIMIT_S
    assert [r.topics for r in rounds] == [1, 5]
    for r in rounds:
        assert r.rosapi_first <= r.rosapi_all
        assert r.mw_first <= r.mw_all
    text = table(rounds)
    assert text.count("\n| 1 | ") == 1 and text.count("\n| 5 | ") == 1
    assert "5 topics: lag median" in text
