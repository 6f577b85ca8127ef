"""B19's smoke form runs, and every message of the burst reaches the reading subscriber,
with and without a slow reader present (docs/limits.md, hold budget)."""

from __future__ import annotations

import functools
import warnings

import pytest
from benchmarks.burst import SMOKE_COUNT, SMOKE_STREAM_FRAMES, run_burst, run_slow_reader
from websockets.sync.client import connect

CLOSE_TIMEOUT_S = 1.0
"""How long a client's close waits for the server's close frame. The slow reader's
frames queue ahead of that frame unread, so its close always waits this long, after
every count is taken (websockets' default is 10 s)."""


def test_burst_smoke_delivers_every_message() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # websockets' sync connect
        results = run_burst(SMOKE_COUNT)
    assert results["rwt"].delivered == results["rwt"].sent == SMOKE_COUNT
    assert results["bare"].delivered == SMOKE_COUNT


def test_slow_reader_variant_smoke_costs_the_others_nothing(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(
        "benchmarks.burst.connect", functools.partial(connect, close_timeout=CLOSE_TIMEOUT_S)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        bursts, streams = run_slow_reader(SMOKE_COUNT, SMOKE_STREAM_FRAMES, ("rwt",))
    assert bursts["rwt"].delivered == SMOKE_COUNT  # the reading subscriber lost nothing
    assert streams["rwt"].bystander == SMOKE_STREAM_FRAMES  # nor did the bystander
    assert streams["rwt"].slow < SMOKE_STREAM_FRAMES  # the slow reader read at its pace
