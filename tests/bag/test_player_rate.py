"""A player's speed is bounded where it is set (``rwt_graph.playback.MIN_RATE``,
``MAX_RATE``: 0.001 to 1000000 times the recorded speed; docs/limits.md, "Bags").

An unbounded speed was taken from anyone who could set it: a Foxglove client set
3.4e38 (tests/foxglove/test_playback.py has its refusal), ``Player(rate=1e300)``
ran until its clock overflowed. Every way in refuses such a speed with a text and
leaves the rate as it was; the terminal's keys stop at the bounds.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

import rwt
from rwt_bag.errors import BagError
from rwt_bag.keys import _actions
from rwt_graph.playback import MAX_RATE, MIN_RATE
from tests.support.cli import run_rwt

from .bags import write_bag

BAD = [3.4028234663852886e38, 1e300, 1_000_000.5, math.inf, -math.inf, math.nan, 0.0, -1.0, 1e-4]
UP, DOWN = b"\x1b[A", b"\x1b[B"


@pytest.fixture
def bag(tmp_path: Path) -> Path:
    return write_bag(tmp_path / "bag", "mcap")


@pytest.mark.parametrize("rate", BAD)
def test_a_speed_outside_the_bounds_is_refused_and_the_rate_stays(bag: Path, rate: float) -> None:
    with pytest.raises(BagError) as refused:
        rwt.bag.Player(rwt.Graph(), bag, rate=rate)
    assert str(refused.value) == (
        f"the rate: speed {rate:g} is not from 0.001 to 1000000 times the recorded speed"
    )
    player = rwt.bag.Player(rwt.Graph(), bag, rate=2.0, paused=True)
    try:
        with pytest.raises(BagError, match=r"is not from 0\.001 to 1000000 times"):
            player.set_rate(rate)
        assert player.rate == 2.0
        player.resume()  # playing: set_rate re-anchors the clock first, so refuse before
        with pytest.raises(BagError):
            player.set_rate(rate)
        assert player.rate == 2.0 and player.bag_time_ns() >= player.start_ns
    finally:
        player.source.close()


def test_the_bounds_themselves_are_taken(bag: Path) -> None:
    player = rwt.bag.Player(rwt.Graph(), bag, rate=MAX_RATE, paused=True)
    try:
        player.set_rate(MIN_RATE)
        assert player.rate == MIN_RATE
    finally:
        player.source.close()


def test_held_arrow_keys_stop_at_the_bounds(bag: Path) -> None:
    player = rwt.bag.Player(rwt.Graph(), bag, paused=True)
    keys = _actions(player)
    try:
        for _ in range(400):  # 1.1 ** 400: far past the bound
            keys[UP]()
        assert player.rate == MAX_RATE
        for _ in range(800):
            keys[DOWN]()
        assert player.rate == MIN_RATE
    finally:
        player.source.close()


def test_rwt_play_refuses_a_rate_past_the_bound_with_one_line(tmp_path: Path, bag: Path) -> None:
    result = run_rwt("play", str(bag), "--port", "0", "--rate", "5e6", cwd=tmp_path)
    assert result.returncode == 1
    assert "the rate: speed 5e+06 is not from 0.001 to 1000000 times the recorded speed" in (
        result.stderr
    )
    assert "Traceback" not in result.stderr
