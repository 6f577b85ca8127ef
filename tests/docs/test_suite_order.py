"""The suite's file order for xdist (tests/support/file_order.py): figures that name real files."""

from __future__ import annotations

from tests.support.file_order import file_seconds, from_durations
from tests.support.realclients import REPO

LOG = """
============================= slowest durations ==============================
19.50s call     tests/benchmarks/test_mcp_latency.py::test_one_round[http]
0.40s setup    tests/benchmarks/test_mcp_latency.py::test_one_round[http]
2.05s call     tests/ros2/test_topics.py::test_a_talker
(3 durations < 0.005s hidden.  Use -vv to show these durations.)
"""


def test_a_durations_report_becomes_seconds_per_file() -> None:
    assert from_durations(LOG) == {
        "tests/benchmarks/test_mcp_latency.py": 19.9,
        "tests/ros2/test_topics.py": 2.0,
    }


def test_the_figures_name_test_files_of_this_checkout() -> None:
    figures = file_seconds()
    assert len(figures) > 300  # the suite's files, measured
    missing = [path for path in figures if not (REPO / path).is_file()]
    assert not missing, f"refresh tests/support/file_seconds.json: {missing[:5]}"
    assert all(path.startswith("tests/") and seconds >= 0 for path, seconds in figures.items())
