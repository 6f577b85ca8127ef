"""The ROS 2 to Foxglove benchmark (benchmarks/ros2_foxglove.py) runs tiny against rwt."""

from __future__ import annotations

import asyncio
import os

import pytest
from benchmarks.ros2_bridge import rclpy_available
from benchmarks.ros2_foxglove import HEIGHT, KINDS, LABELS, WIDTH, cdr_stamp, run, table

import rwt

#: Clear of tests/ros2's domains (from 150), the benchmark's default (130-139) and
#: test_ros2_bridge.py's (140-149, same pid rule): its own slot per process.
DOMAIN = 100 + os.getpid() % 10


def _image_cdr(sec: int, nanosec: int, frame_id: str) -> bytes:
    registry = rwt.Graph().registry
    mtype = registry.message("sensor_msgs/msg/Image")
    msg = {
        "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id},
        "height": 2,
        "width": 2,
        "encoding": "rgb8",
        "step": 6,
        "data": bytes(12),
    }
    return bytes(registry.serialize(mtype, mtype.from_python(msg)))


def test_the_stamp_comes_from_the_cdr_header_and_a_probe_has_none() -> None:
    assert cdr_stamp(_image_cdr(1_700_000_000, 250_000_000, "cam")) == 1_700_000_000.25
    assert cdr_stamp(_image_cdr(5, 0, "probe")) is None
    with pytest.raises(ValueError, match="no Image header"):
        cdr_stamp(b"\x00\x01\x00\x00")


@pytest.mark.skipif(
    not rclpy_available(), reason='rclpy is not importable: pip install "rwt-rosbridge[ros2]"'
)
def test_every_image_reaches_the_foxglove_cbor_raw_and_json_readers() -> None:
    """Lightly paced: every kind of reader gets every image (the JSON ones check each
    image's base64 in place, a wrong delivery fails the round)."""
    rounds = asyncio.run(run(1, 1.0, [10], list(KINDS), DOMAIN, readers=2))
    assert [r.kind for r in rounds] == list(KINDS)
    for figures in rounds:
        assert figures.sent >= 8
        assert figures.delivered == 2 * figures.sent
        assert figures.delivered_pct == 100.0
        assert 0 <= figures.p50_ms <= figures.p99_ms
        assert figures.cpu_us_per_delivery > 0
    text = table(rounds)
    for figures in rounds:
        row = f"| {LABELS[figures.kind]} | {figures.sent} | 100.0 | "
        assert row in text
    assert "| 10 Hz, 2 readers (1 rounds) | Foxglove (foxglove.sdk.v1, CDR) |" in text
    assert WIDTH * HEIGHT * 3 >= 1_000_000
