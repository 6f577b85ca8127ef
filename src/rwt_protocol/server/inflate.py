"""Inflating ``png`` ops, charged to the connection that sends them (docs/limits.md).

A ``png`` op of 17 KB can inflate to 9 MB; done on the event loop, one after
another, a sender of such ops held every other connection up. So each
connection has a ``TokenBucket`` of inflated bytes (``--png-inflate-rate`` per
second, a burst of ``--max-message-size``), and a ``png`` op becomes an
``InflateJob``: its transport waits until the job's ``ready_at`` (the sender's
reader waits, no one else), runs ``InflateJob.run`` in a worker thread, and hands
the result back (``Session.finish_job``). Nothing here reads a clock or starts a
thread: ``now`` comes from the caller.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..codecs.png import PendingPng

__all__ = ["InflateJob", "TokenBucket"]


class TokenBucket:
    """A budget of ``rate`` units a second, of which ``burst`` can be spent at once.

    Spending never fails: ``charge`` takes the cost, possibly into debt, and says
    how long its caller must wait for the debt to be paid off, so a sender that
    goes on simply waits longer.

    Args:
        rate: units (bytes) regained per second, above 0.
        burst: the most units held (the bucket starts full).
    """

    __slots__ = ("_level", "_updated", "burst", "rate")

    def __init__(self, rate: float, burst: float) -> None:
        self.rate = rate
        self.burst = burst
        self._level = burst
        self._updated: float | None = None

    def charge(self, cost: float, now: float) -> float:
        """Spend ``cost`` units at monotonic ``now``; return the seconds to wait (0: none)."""
        if self._updated is not None:
            self._level = min(self.burst, self._level + (now - self._updated) * self.rate)
        self._updated = now
        self._level -= cost
        return 0.0 if self._level >= 0 else -self._level / self.rate


@dataclass(frozen=True, slots=True)
class InflateJob:
    """One ``png`` op to inflate, for the session's transport to run.

    Attributes:
        png: the checked PNG (``png.read_png``).
        op_id: the ``id`` of the ``png`` op, for its error status.
        ready_at: monotonic seconds before which it must not run (its sender's budget).
    """

    png: PendingPng
    op_id: str | int | None
    ready_at: float

    def run(self) -> bytes:
        """Inflate the PNG (CPU only, no shared state: safe in a worker thread).

        Raises:
            RemoteProtocolError: the compressed data is corrupt.
        """
        return self.png.inflate()
