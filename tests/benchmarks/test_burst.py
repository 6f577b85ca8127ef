"""B19's smoke form runs, and every message of the burst reaches the reading subscriber."""

from __future__ import annotations

import warnings

from benchmarks.burst import SMOKE_COUNT, run_burst


def test_burst_smoke_delivers_every_message() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # websockets' sync connect
        results = run_burst(SMOKE_COUNT)
    assert results["rwt"].delivered == results["rwt"].sent == SMOKE_COUNT
    assert results["bare"].delivered == SMOKE_COUNT
