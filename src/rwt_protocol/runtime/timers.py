"""A sans-IO timer queue: deadlines in, due callbacks out (aioquic's get_timer/handle_timer).

The session owns one; handlers schedule work (throttle windows, call timeouts,
fragment expiry) and the transport calls ``Session.handle_timer(now)`` when
``Session.get_timer()`` says so. Nothing here reads a clock.
"""

from __future__ import annotations

import heapq
import itertools
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["Timer", "TimerQueue"]


class Timer:
    """A scheduled callback; ``cancel()`` it to keep it from running."""

    __slots__ = ("callback", "cancelled", "deadline")

    def __init__(self, deadline: float, callback: Callable[[float], None]) -> None:
        self.deadline = deadline
        self.callback = callback
        self.cancelled = False

    def cancel(self) -> None:
        """Do not run this timer."""
        self.cancelled = True


class TimerQueue:
    """Timers ordered by deadline (monotonic seconds)."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Timer]] = []
        self._order = itertools.count()

    def schedule(self, deadline: float, callback: Callable[[float], None]) -> Timer:
        """Run ``callback(now)`` at the first ``run_due(now)`` with ``now >= deadline``."""
        timer = Timer(deadline, callback)
        heapq.heappush(self._heap, (deadline, next(self._order), timer))
        return timer

    def next_deadline(self) -> float | None:
        """The earliest deadline of a live timer, or None."""
        while self._heap and self._heap[0][2].cancelled:
            heapq.heappop(self._heap)
        return self._heap[0][0] if self._heap else None

    def run_due(self, now: float, on_error: Callable[[Exception], None]) -> None:
        """Run every live timer whose deadline is at or before ``now``, earliest first.

        Args:
            now: monotonic seconds.
            on_error: given what a callback raised; the later timers still run
                (the session contains it, ``SessionBase.handle_timer``).
        """
        while self._heap and self._heap[0][0] <= now:
            _, _, timer = heapq.heappop(self._heap)
            if not timer.cancelled:
                timer.cancelled = True
                try:
                    timer.callback(now)
                except Exception as exc:  # a bug in one timer: the others still run
                    on_error(exc)

    def clear(self) -> None:
        """Drop every timer."""
        self._heap.clear()
