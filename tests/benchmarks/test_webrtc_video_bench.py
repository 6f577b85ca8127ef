"""The WebRTC video benchmark's bandwidth rows in a small form: their sense, not their speed."""

from __future__ import annotations

import pytest

pytest.importorskip("aiortc", exc_type=ImportError)

from benchmarks.webrtc_video import bandwidth_rows


def test_bandwidth_rows_beside_table_one() -> None:
    rows = {str(row["stream"]): row for row in bandwidth_rows(10)}
    mjpeg = float(rows["MJPEG quality 90 (HTTP)"]["kb_per_s"])  # type: ignore[arg-type]
    for codec in ("vp8", "h264"):
        low = rows[f"{codec} 100 kbit/s (WebRTC track)"]
        high = rows[f"{codec} 1000 kbit/s (WebRTC track)"]
        assert 0 < float(low["kb_per_s"]) < float(high["kb_per_s"]) < mjpeg  # type: ignore[arg-type]
        assert int(low["rtp_packets"]) >= 10  # type: ignore[call-overload]  # a packet a frame at least
    assert rows["MJPEG quality 90 (HTTP)"]["vs_mjpeg"] == 1.0
