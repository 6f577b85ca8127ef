"""The ROS 2 edition of the peer benchmark (benchmarks/peer_ros2.py) runs tiny against rwt."""

from __future__ import annotations

import asyncio

import pytest
from benchmarks.peer import main as peer_main
from benchmarks.peer_ros2 import WebCase, run_case, table


def test_a_paced_stream_and_a_burst_reach_every_subscriber_through_rwt() -> None:
    paced = asyncio.run(run_case("rwt", WebCase(20, 2), 1.0, 0))
    assert paced.sent >= 15
    assert paced.delivered == 2 * paced.sent  # lightly paced: nothing lost
    burst = asyncio.run(run_case("rwt", WebCase(0, 1, count=300), 1.0, 0))
    assert (burst.sent, burst.delivered, burst.loss) == (300, 300, 0)
    assert 0 <= burst.p50_ms <= burst.p99_ms
    rows = table([paced, burst]).splitlines()
    assert rows[2].startswith("| String 100 B 20 Hz 1->2 | rwt serve --dialect ros2 |")
    assert rows[3].startswith("| String 100 B burst 300 1->1 | rwt serve --dialect ros2 | 300 |")


def test_the_peer_command_skips_the_ros2_peers_it_is_not_given(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("RWT_ROSBRIDGE_ROS2_DIR", raising=False)
    monkeypatch.delenv("RWT_ROSBRIDGE_RS_DIR", raising=False)
    assert peer_main(["--edition", "ros2", "--receivers", "rosbridge,rs"]) == 0
    out = capsys.readouterr().out
    assert "rosbridge_suite 2.1.0 skipped: RWT_ROSBRIDGE_ROS2_DIR" in out
    assert "rosbridge-server-rs 0.1.6 skipped: RWT_ROSBRIDGE_RS_DIR" in out
