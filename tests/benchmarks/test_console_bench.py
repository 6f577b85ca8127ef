"""``python -m benchmarks console --quick`` runs: every phase measures something, and a
graph refresh touches only the rows that changed (benchmarks/README.md, console)."""

from __future__ import annotations

import pytest
from benchmarks.console import QUICK, measure, table

from tests.browser.cdp import chromium_path

pytestmark = pytest.mark.skipif(
    chromium_path() is None, reason="chromium is not installed (apt-get install chromium)"
)


def test_console_benchmark_smoke() -> None:
    results = measure(QUICK)
    assert results["page_errors"] == []
    listed = results["list"]
    assert listed["rows_listed"] >= QUICK.topics
    assert listed["rows_touched_unchanged"] == []  # a refresh with nothing new writes nothing
    assert listed["rows_touched_added"] == ["/bench/added"]  # only the new row
    assert results["echo"]["input_handled"] > 0
    assert results["echo"]["input_p99_ms"] is not None
    assert results["mjpeg"]["frames_per_s"] > 0
    assert results["vp8"]["frames_per_s"] > 0
    assert "| input latency p50 / p99" in table(results)
