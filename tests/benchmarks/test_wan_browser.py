"""The browser WAN benchmark in a small form: Chromium behind the link gets every row.

Its sense, not its speed: a short run at 100 Hz across a clean link, on the stacks
that import here, each row with messages, ages and the robot's CPU.
"""

from __future__ import annotations

import pytest

pytest.importorskip("aiortc", exc_type=ImportError)

from benchmarks.wan_browser import available_stacks, figures, run
from benchmarks.wanlink import LinkProfile

from tests.browser.cdp import chromium_path
from tests.support import netns
from tests.webrtc.pagesite import MODULES


def test_figures_count_the_missing_and_the_stalls() -> None:
    rows: list[float] = []
    for seq in range(1, 401):
        if seq in (200, 201):  # two lost
            continue
        arrival = seq + (150 if seq > 300 else 0)  # one stall of 151 ms
        rows += [arrival, arrival - 40, seq]
    got = figures(rows, warmup_s=0.0)
    assert got["received"] == 398
    assert got["missing"] == 2
    assert got["stalls"] == 1 and got["longest_gap_ms"] == 151
    assert got["age_p50_ms"] == 40


def test_chromium_behind_the_link_gets_each_stack_and_the_websocket() -> None:
    reason = netns.unavailable(("tun",))
    if reason is not None:
        pytest.skip(reason)
    if chromium_path() is None:
        pytest.skip("chromium is not installed")
    if not (MODULES / "roslib").is_dir():
        pytest.skip("roslib is not installed: npm ci --prefix tests/js")
    clean = LinkProfile(delay_s=0.005, jitter_s=0.0, loss=0.0, rate_bps=15e6)
    stacks = available_stacks()
    rows = {row["transport"]: row for row in run(stacks, 3.0, 100.0, clean, warmup_s=0.5)}
    expected = {f"{s}-{kind}" for s in stacks for kind in ("reliable", "lossy", "vp8")}
    assert set(rows) == expected | {"websocket"}, rows
    for name, row in rows.items():
        assert "failure" not in row, row
        if name.endswith("-vp8"):  # the camera's track beside the topic: frames presented
            assert row["received"] > 0 and row["age_p50_ms"] > 5, row
            continue
        assert row["received"] >= 100, row  # 2.5 s at 100 Hz, whatever the load
        assert row["age_p50_ms"] > 5, row  # the link's delay is in every age
        assert row["robot_cpu_us_per_msg"] > 0, name
        if not name.endswith("-lossy"):
            assert row["missing"] == 0, row  # reliable: every message between the first and last
