"""B22 smoke: rwt and the real ROS 1 rosbag record and play, one tiny round each.

Runs on Debian's ROS 1 (roscore, rosbag, python3-rospy); skipped with the reason
when they are absent. Figures of a tiny round mean nothing: only what reached the
bags and the subscribers is asserted.
"""

from __future__ import annotations

import pytest
from benchmarks.__main__ import main

from benchmarks import ros1_bag

MISSING = ros1_bag.missing()
RECORD = "record String 100 B, as fast as the publisher goes"
PLAY = "play 300 String 100 B at full speed"


def test_without_ros1_the_benchmark_says_why_it_skips(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("PATH", "/nonexistent")
    assert ros1_bag.missing() == "roscore is not installed (Debian: ros-core, python3-rosbag)"
    assert main(["rosbag", "--smoke"]) == 0
    assert "benchmarks rosbag: skipped: roscore is not installed" in capsys.readouterr().err


@pytest.mark.skipif(MISSING is not None, reason=f"B22 needs Debian's ROS 1: {MISSING}")
def test_one_tiny_round_records_and_plays_on_both_sides() -> None:
    result = ros1_bag.run(1, smoke=True, log=lambda _: None)
    rows = {row["measure"]: row for row in result["rows"]}  # type: ignore[attr-defined]
    assert list(rows) == [RECORD, PLAY]
    record = rows[RECORD]
    # rwt's bag holds every message its client published; rosbag's drops are reported
    assert record["rwt"]["in_bag"] == record["rwt"]["sent"] > 0
    assert record["ros1"]["in_bag"] > 0
    for side in ("rwt", "ros1"):  # each subscriber got the whole bag, checked message by message
        assert rows[PLAY][side]["in_bag"] == rows[PLAY][side]["sent"] == 300
    text = ros1_bag.table(result)
    assert f"| {RECORD} |" in text and f"| {PLAY} |" in text
