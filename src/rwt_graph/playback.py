"""What a player of recorded data offers to whoever drives it from outside.

While a bag plays into the graph (``rwt_bag.player.Player``), the graph's core
holds it as its ``playback`` next to its ``timeline`` (``GraphCore.use_timeline``),
so a protocol that can drive playback (Foxglove's ``playbackControl``,
docs/foxglove.md) finds it without importing the player. Times are
nanoseconds since the epoch on the recording's clock.
"""

from __future__ import annotations

from enum import Enum
from typing import Protocol

__all__ = ["Playback", "PlaybackStatus"]


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
        """Play on at ``rate`` (a finite number above 0) from the position."""

    def seek_ns(self, time_ns: int) -> None:
        """Go to ``time_ns``, moved into ``time_range_ns`` when outside it."""
