"""Z2's raw-socket generator counts every delivery of a real `rwt serve`, and only those."""

from __future__ import annotations

from pathlib import Path

from benchmarks.fanout_raw import fan_out_raw

from tests.integration.client_harness import ServerProcess


def test_every_subscriber_gets_every_timed_message(tmp_path: Path) -> None:
    server = ServerProcess(tmp_path, ("--no-tf",))
    try:
        result = fan_out_raw(server.port, 5, 0.3, window=16)
    finally:
        server.stop()
    assert result["sent"] > 0
    assert result["delivered"] == result["expected"] == result["sent"] * 5
    assert result["deliveries_per_s"] > 0
