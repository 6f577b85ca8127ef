"""What a player of recorded data offers to whoever drives it from outside.

While a bag plays into the graph (``rwt_bag.player.Player``), the graph's core
holds it as its ``playback`` next to its ``timeline`` (``GraphCore.use_timeline``),
so a protocol that can drive playback (Foxglove's ``playbackControl``,
docs/foxglove.md) finds it without importing the player. Times are
nanoseconds since the epoch on the recording's clock.

The speed a player takes is bounded here once, for every way of setting it
(``rwt play --rate``, the terminal's keys, Foxglove's playback bar, Python):
``rate_problem`` says why a speed is refused.
"""

from __future__ import annotations

import math
from enum import Enum
from typing import Final, Protocol

__all__ = ["MAX_RATE", "MIN_RATE", "Playback", "PlaybackStatus", "rate_problem"]

#: The slowest speed factor a player takes: a thousandth of the recorded speed, the
#: least ``rwt play --rate`` takes (below it a second of the bag lasts over 16 minutes).
MIN_RATE: Final = 0.001
#: The fastest: a million times the recorded speed (a day of bag in 86 ms), which for
#: any real bag is "as fast as it can", as rosbag's ``--immediate``: rwt's own
#: benchmarks play at ``--rate 1e6`` for that. Foxglove's and Lichtblick's playback
#: bars offer 0.01x to 5x; ``ros2 bag play --rate`` and rosbag's ``-r`` take any
#: positive number. Unbounded, a Foxglove client set 3.4e38 (the largest 32-bit
#: float), and a rate near the largest double made the player's clock overflow
#: (``int(inf)`` nanoseconds) once it had run a while.
MAX_RATE: Final = 1_000_000.0


def rate_problem(rate: float) -> str | None:
    """Why ``rate`` is not a speed a player takes, or None when it is.

    Args:
        rate: a speed factor (1.0: as recorded).

    Returns:
        None for a finite number from ``MIN_RATE`` to ``MAX_RATE``; else a text
        such as ``speed 3.40282e+38 is not from 0.001 to 1000000 times the
        recorded speed`` (NaN, infinities, 0 and negative numbers too).
    """
    if math.isfinite(rate) and MIN_RATE <= rate <= MAX_RATE:
        return None
    return f"speed {rate:g} is not from {MIN_RATE:g} to {MAX_RATE:.0f} times the recorded speed"


class PlaybackStatus(Enum):
    """Where playback is: moving, held, or past its last message (and not looping)."""

    PLAYING = "playing"
    PAUSED = "paused"
    ENDED = "ended"


class Playback(Protocol):
    """A player as the graph offers it to protocols (``GraphCore.playback``)."""

    @property
    def time_range_ns(self) -> tuple[int, int]:
        """The first and the last time that ``seek_ns`` reaches (ns since the epoch)."""
        ...

    @property
    def status(self) -> PlaybackStatus:
        """Playing, paused, or ended (the end was reached and nothing plays any more)."""
        ...

    @property
    def rate(self) -> float:
        """The speed factor (1.0: as recorded)."""
        ...

    @property
    def jumps(self) -> int:
        """How many times the position jumped so far (a seek, a loop's restart)."""
        ...

    def clock_ns(self) -> int:
        """The playback position now (ns since the epoch); the graph's ``timeline``."""
        ...

    def pause(self) -> None:
        """Hold the position; nothing is published until ``resume``."""

    def resume(self) -> None:
        """Play on from the position."""

    def set_rate(self, rate: float) -> None:
        """Play on at ``rate`` from the position; a rate ``rate_problem`` refuses raises.

        A driver that must refuse a whole request (Foxglove's) asks
        ``rate_problem`` first, so that nothing of it is applied.
        """

    def seek_ns(self, time_ns: int) -> None:
        """Go to ``time_ns``, moved into ``time_range_ns`` when outside it."""
