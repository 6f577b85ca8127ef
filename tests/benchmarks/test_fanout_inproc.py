"""The in-process fan-out benchmark runs both protocols and counts every delivery."""

from __future__ import annotations

from benchmarks.fanout_inproc import PROTOCOLS, fan_out


def test_every_session_of_each_protocol_gets_every_publish() -> None:
    for protocol in PROTOCOLS:
        us_per_publish, delivered = fan_out(protocol, 3, 4)
        assert delivered == 3 * 4, protocol
        assert us_per_publish > 0
