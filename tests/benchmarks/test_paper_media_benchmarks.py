"""The paper benchmarks of Tables I and II in quick mode: the rows' contract and their sense."""

from __future__ import annotations

import math

from benchmarks.paper import depthcloud, video

KEYS = {"figure", "metric", "paper", "ours", "unit", "note"}


def by_metric(rows: list[dict[str, object]]) -> dict[str, float]:
    assert all(set(row) == KEYS for row in rows)
    return {str(row["metric"]): float(row["ours"]) for row in rows}  # type: ignore[arg-type]


def test_table_one_rows() -> None:
    rows = video.run(quick=True)
    assert {row["figure"] for row in rows} == {"Table I"}
    ours = by_metric(rows)
    raw = ours["raw Image over rosbridge, CBOR"]
    assert raw > 27_000  # 640x480x3 bytes at 30 Hz, in KB/s
    assert ours["raw Image over rosbridge, JSON"] > raw  # base64
    assert (
        0
        < ours["VP8 100 kbit/s (/stream?type=vp8)"]
        < ours["MJPEG quality 90 (/stream?type=mjpeg)"]
        < raw / 5
    )


def test_table_two_rows() -> None:
    rows = depthcloud.run(quick=True)
    ours = by_metric(rows)
    cloud = ours["PointCloud2 over rosbridge, CBOR"]
    for codec in ("VP8 100 kbit/s", "MJPEG quality 90"):
        assert ours[f"depth cloud as {codec}"] < cloud / 10  # the paper's 90 % less
        error = ours[f"depth cloud as {codec}: median depth error"]
        assert math.isfinite(error) and error < 100
