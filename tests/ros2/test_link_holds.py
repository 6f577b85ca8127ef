"""A slow reader of one ROS 2 topic holds no other topic of the link (`rwt serve --ros2`).

A real rclpy node publishes ``/cam`` (100 KB at 100 msg/s) and ``/odom`` (50
msg/s). One client reads ``/cam`` 64 KB every 0.5 s over a small receive
buffer; another subscribes only to ``/odom``. The link holds ``/cam`` while its
reader is congested, within the hold budget, and ``/odom`` goes on at full
rate. Before, the whole link was held: ``/odom`` stood still most of the run,
in gaps of about the hold budget.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from tests.hardening.link_readers import Bystander, SlowReader, wait_until

from .support import Peer, serve_ros2, skip_without_rclpy

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = skip_without_rclpy()

ODOM_MESSAGES = 200  # the window: 4 s at 50 msg/s, twice the hold budget
STILL_S = 0.2  # a gap longer than ten periods counts as standing still
LONGEST_GAP_S = 1.0  # half the hold budget: the held link stood still a whole budget at a time
FROZEN_SHARE = 0.25  # of the window: a loaded machine's own stalls add up to 10-15 % of it


def test_a_slow_camera_reader_holds_up_no_other_topic(ros_env: Path) -> None:
    server = serve_ros2(ros_env, "--hold-budget", "2")
    try:
        with Peer("camodom", "/cam", ros_env):
            odom = Bystander(server.url, "/odom", "std_msgs/String")
            cam = SlowReader(server.url, "/cam", "sensor_msgs/Image")
            try:
                wait_until(lambda: odom.data and cam.received > 0, "both topics to flow")
                start, first = time.monotonic(), len(odom.data)
                wait_until(lambda: len(odom.data) >= first + ODOM_MESSAGES, "/odom", 60.0)
                end = time.monotonic()
            finally:
                cam.close()
                odom.close()
        stderr = server.stderr_text()
    finally:
        server.stop()
    frozen = odom.frozen(start, end, STILL_S)
    assert frozen.longest_s < LONGEST_GAP_S, (frozen, stderr[-2000:])
    assert frozen.total_s < FROZEN_SHARE * frozen.window_s, (frozen, stderr[-2000:])
    counts = [int(msg["data"]) for msg in odom.data[first:]]
    assert len(counts) >= 0.9 * (counts[-1] - counts[0] + 1)  # full rate: next to no loss
