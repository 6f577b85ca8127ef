"""The ROS 2 bridge benchmark (benchmarks/ros2_bridge.py) runs tiny against ``rwt serve --ros2``."""

from __future__ import annotations

import asyncio
import os

import pytest
from benchmarks.ros2_bridge import (
    CASES,
    FASTDDS,
    Case,
    Result,
    rclpy_available,
    ros_env,
    run_case,
    stage_table,
    summary,
    table,
)

pytestmark = pytest.mark.skipif(
    not rclpy_available(), reason='rclpy is not importable: pip install "rwt-rosbridge[ros2]"'
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
    # rwt's per-stage counts (its log): every timed sample at every stage; the first
    # probes may go before the link's subscription has matched (discovery)
    stages = result.stages
    assert stages is not None
    assert result.probes >= 1
    assert stages["sent"] == result.sent + result.probes
    assert result.sent < stages["taken"] <= stages["sent"]
    assert stages["taken"] == stages["handed"] == stages["published"]
    assert stages["refused"] == 0
    assert sum(v for k, v in stages.items() if k.startswith("batch_")) == stages["wakes"]
    assert stages["queued"] == 2 * stages["published"]  # each subscriber's queue
    assert stages["dropped"] == 0
    assert stages["written"] >= stages["queued"]
    assert f"| String 100 B 20 Hz | 2 | {stages['sent']} | {stages['taken']} |" in stage_table(
        [result]
    )


def test_the_5khz_rows_and_the_rounds_summary() -> None:
    """``--rounds``: medians with each round's spread; 5 kHz rows for 1 and 10 subscribers."""
    assert {(c.hz, c.subscribers) for c in CASES if c.kind == "string"} >= {(5000, 1), (5000, 10)}
    rounds = [
        Result("rwt", "String 100 B 5000 Hz", 1, 25000, d, d / 5, 1 - d / 25000, 0.5, p99, 90)
        for d, p99 in ((24000, 3.0), (25000, 2.0), (20000, 40.0))
    ]
    row = summary(rounds).splitlines()[-1]
    assert row.startswith(
        "| String 100 B 5000 Hz | 1 | rwt serve --ros2 | 3 | 4,800 (4,000-5,000) |"
    )
    assert "| 4.0 (0.0-20.0) % |" in row  # loss, median (min-max)
    assert "| 3.0 (2.0-40.0) |" in row  # p99 ms


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
