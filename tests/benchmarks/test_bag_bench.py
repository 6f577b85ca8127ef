"""B20 smoke: every message recorded and replayed on both sides, and the timing measured."""

from __future__ import annotations

from benchmarks.bag import run, table


def test_bag_benchmark_smoke() -> None:
    result = run(1, smoke=True)
    measures = [row["measure"] for row in result["rows"]]  # type: ignore[attr-defined]
    assert measures == [
        "record 100 B strings",
        "replay 100 B strings",
        "record 1 MB images",
        "replay 1 MB images",
    ]
    for row in result["rows"]:  # type: ignore[attr-defined]
        assert row["rwt_msg_s"] > 0 and row["rosbags_msg_s"] > 0
    assert 0 <= result["timing_p50_ms"] <= result["timing_p99_ms"]  # type: ignore[operator]
    assert "| record 1 MB images (5) |" in table(result)
