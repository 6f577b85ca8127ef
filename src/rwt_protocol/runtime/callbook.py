"""One connection's calls in flight, for every protocol: a cap, a deadline, one answer.

A rosbridge ``call_service`` and a Foxglove ``serviceCallRequest`` are the same
thing to the server: a call into the graph that holds the connection until it is
answered. The book counts them against ``--max-pending-calls``, gives each a
deadline timer of its own (``--call-timeout``; the session's timers, so never
late by a poll), and settles each exactly once: by its answer, by its deadline
(the graph is told to forget it, so a late answer goes nowhere) or by the
connection's close. The protocol says what the caller hears in each case.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from collections.abc import Callable

    from .timers import Timer

__all__ = ["BookedCall", "CallBook"]


class _Forgettable(Protocol):
    def forget(self) -> None:
        """The caller no longer waits: a late answer goes nowhere."""


class BookedCall:
    """One call in the book until it is settled.

    Attributes:
        pending: the graph's handle of the call (``forget`` on expiry or close),
            set once the graph took it.
        on_close: called if the connection closes before the call is settled
            (a caller in the process that waits for it); None: nobody to tell.
    """

    __slots__ = ("_book", "_timer", "on_close", "pending", "settled")

    def __init__(self, book: CallBook, on_close: Callable[[], None] | None = None) -> None:
        self._book = book
        self._timer: Timer | None = None
        self.pending: _Forgettable | None = None
        self.on_close = on_close
        self.settled = False

    def settle(self) -> bool:
        """Take the call out of the book; True the first time only (its answer goes then)."""
        if self.settled:
            return False
        self.settled = True
        self._book._open.discard(self)
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        return True

    def _expire(self, on_expire: Callable[[float], None], now: float) -> None:
        if self.settle():
            if self.pending is not None:
                self.pending.forget()
            on_expire(now)


class CallBook:
    """The calls one connection has in flight.

    Args:
        call_at: the session's timers (``SessionBase.call_at``).
        max_pending: calls in flight at once (``--max-pending-calls``).
        timeout_s: the default deadline in seconds (``--call-timeout``); None: none.
    """

    def __init__(
        self,
        call_at: Callable[[float, Callable[[float], None]], Timer],
        max_pending: int,
        timeout_s: float | None,
    ) -> None:
        self._call_at = call_at
        self.max_pending = max_pending
        self.timeout_s = timeout_s
        self._open: set[BookedCall] = set()

    @property
    def in_flight(self) -> int:
        """Calls booked and not settled."""
        return len(self._open)

    @property
    def full(self) -> bool:
        """Whether a new call would pass ``max_pending``."""
        return len(self._open) >= self.max_pending

    def book(self, on_close: Callable[[], None] | None = None) -> BookedCall:
        """Book a call (the caller checked ``full``); ``expire_at`` then gives its deadline.

        ``on_close``: what to tell its caller if the connection closes first.
        """
        call = BookedCall(self, on_close)
        self._open.add(call)
        return call

    def expire_at(
        self, call: BookedCall, deadline: float, on_expire: Callable[[float], None]
    ) -> None:
        """At monotonic ``deadline`` settle ``call`` unless answered, then ``on_expire(now)``.

        A call settled already gets no timer.
        """
        if not call.settled:
            call._timer = self._call_at(deadline, lambda now: call._expire(on_expire, now))

    def close(self) -> None:
        """The connection is gone: settle every call, the graph forgets each (no answer goes)."""
        calls, self._open = self._open, set()
        for call in calls:
            call.settle()
            if call.pending is not None:
                call.pending.forget()
            if call.on_close is not None:
                call.on_close()
