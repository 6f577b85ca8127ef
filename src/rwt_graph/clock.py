"""Clocks the graph reads: monotonic time for ordering, wall time for stamps."""

from __future__ import annotations

import time
from typing import Protocol

__all__ = ["Clock", "SystemClock"]


class Clock(Protocol):
    """A source of time, injectable so tests control it."""

    def monotonic(self) -> float:
        """Seconds on a clock that never goes back (timers, throttling)."""

    def wall(self) -> float:
        """Seconds since the Unix epoch (header stamps, ``"now"``, rosapi get_time)."""


class SystemClock:
    """The process's real clocks: ``monotonic`` is ``time.monotonic``, ``wall`` ``time.time``.

    The functions themselves, not methods that call them: the graph reads both
    for every message it publishes.
    """

    monotonic = staticmethod(time.monotonic)
    wall = staticmethod(time.time)
