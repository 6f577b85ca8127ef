"""The many-viewers video benchmark's smoke form runs: every viewer gets frames and the
rosbridge bystander's round trips are answered in each case (benchmarks/video_viewers.py)."""

from __future__ import annotations

from benchmarks.video_viewers import measure


def test_video_viewers_smoke_serves_the_viewers_and_the_bystander() -> None:
    cases = [("idle", 0), ("one stream", 3), ("3 streams", 3)]
    results = measure([("rwt", None)], cases, runs=1, seconds=1.0, camera=(320, 240, 15.0))
    assert [r.case for r in results] == ["idle", "one stream", "3 streams"]
    assert all(r.round_trips > 0 for r in results)
    assert [r.frames_per_s > 0 for r in results] == [False, True, True]
