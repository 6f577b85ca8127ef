"""The token bucket that paces png inflating (docs/limits.md, rwt_protocol.server.inflate)."""

from __future__ import annotations

import pytest

from rwt_protocol.server.inflate import TokenBucket


def test_a_burst_goes_at_once_then_the_rate_paces() -> None:
    bucket = TokenBucket(rate=100, burst=300)
    assert bucket.charge(300, now=10.0) == 0.0  # the burst
    assert bucket.charge(100, now=10.0) == pytest.approx(1.0)  # one second of debt
    assert bucket.charge(100, now=10.0) == pytest.approx(2.0)  # going on waits longer
    assert bucket.charge(150, now=13.0) == pytest.approx(0.5)  # 300 regained, 200 were owed


def test_a_quiet_bucket_refills_only_to_its_burst() -> None:
    bucket = TokenBucket(rate=100, burst=300)
    bucket.charge(0, now=0.0)
    assert bucket.charge(300, now=1000.0) == 0.0
    assert bucket.charge(1, now=1000.0) > 0.0
