"""B26's churn soak (benchmarks/churn.py) runs for seconds: every front end's cycle passes.

Figures of a few seconds mean nothing; what is checked is that each front end's real
client completed its cycles without a failure, the steady subscriber got every message,
and the curve and the summary were written. The ROS 2 fronts run in a test of their own,
skipped where rclpy does not import.
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import pytest
from benchmarks.churn_report import table

from benchmarks import churn

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")
pytest.importorskip("aiortc", reason="aiortc is not installed (the webrtc or test extra)")

#: Clear of tests/ros2's domains (from 150) and the other benchmarks' (100-149).
DOMAIN = 90 + os.getpid() % 5
WEB = ("rosbridge", "foxglove", "http", "mcp", "webrtc")


def _short(out: Path, fronts: tuple[str, ...], ros2: bool) -> churn.Config:
    rates = {name: (hz if name in fronts else 0.0) for name, hz in churn.RATES.items()}
    return churn.Config(
        minutes=0.1,
        warmup_minutes=0.02,
        sample_s=0.5,
        rates=rates,
        ros2=ros2,
        drain_s=1.0,
        out=out,
        domain=DOMAIN,
    )


def _check(record: dict[str, object], out: Path, fronts: tuple[str, ...]) -> None:
    tallies = record["fronts"]
    assert isinstance(tallies, dict)
    assert set(tallies) == set(fronts)
    for name, tally in tallies.items():
        assert tally["cycles"] >= 1 and tally["failed"] == 0, (name, tally)
    steady = record["steady"]
    assert isinstance(steady, dict)
    assert steady["final"] and steady["got"] == steady["sent"] > 0 and steady["missing"] == 0
    with (out / "churn.csv").open() as curve:
        rows = list(csv.DictReader(curve))
    assert {row["phase"] for row in rows} == {"churn", "drain"}
    assert all(float(row["rss_mb"]) > 0 for row in rows)
    saved = json.loads((out / "churn.json").read_text())
    assert saved["summary"]["rss_warm_mb"] > 0 and len(saved["samples"]) == len(rows)
    assert record["verdict"].endswith("steady served")  # type: ignore[union-attr]
    assert "| rosbridge |" in table(record) or "| ros2 |" in table(record)


def test_every_web_front_end_churns_beside_a_steady_subscriber(tmp_path: Path) -> None:
    record = churn.run(_short(tmp_path, WEB, ros2=False))
    _check(record, tmp_path, WEB)
    assert record["log"]["tracebacks"] == 0  # type: ignore[index]


def test_rclpy_nodes_and_link_subscriptions_churn(tmp_path: Path) -> None:
    env = churn.ros2_environment(DOMAIN)
    if env is None or not churn.rclpy_imports(env):
        pytest.skip('rclpy is not importable: pip install "rwt-rosbridge[ros2]"')
    fronts = ("ros2-link", "ros2")
    record = churn.run(_short(tmp_path, fronts, ros2=True))
    _check(record, tmp_path, fronts)
