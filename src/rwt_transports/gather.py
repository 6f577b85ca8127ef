"""Output made outside a reader's batch, gathered over turns of the event loop.

A publisher in the server's process (``Graph.create_publisher``, a link's
deliveries, a player) that yields to the event loop after each message hands
each subscriber one message a turn. Written as it comes, that is one system
call per message and connection: most of the cost of a burst of small
messages. Output made inside a reader's batch is written at the batch's end
(``pump.flush_deferred``); output made outside one joins the loop's
``Gatherer`` (one for every connection of the loop, whatever its protocol),
which puts the writes off while output keeps coming. It looks twice, on the
next two turns: if the second turn brought no new output it writes then (the
first look runs before the publisher that caused the gathering has had its
next turn, so it cannot tell a burst from a lone message); if it did, the
output is a burst, written when ``GATHER_S`` have passed since the gathering
began, with no look in between. A connection that has ``GATHER_BYTES`` queued
is written at once (``release``). A lone message so waits two turns of the
loop; a message of a burst at most ``GATHER_S`` (on uvloop, whose timers count
whole milliseconds, up to half a millisecond more). A gathering's age is read
on ``time.monotonic``, not the loop's clock: uvloop's ``loop.time`` moves in
whole milliseconds, so a 1 ms gathering seemed over at its second look and a
burst went out a few messages a write. Part of the ``deferred-send`` shortcut:
off, every output wakes its connection's writer.
"""

from __future__ import annotations

import time
import weakref
from typing import TYPE_CHECKING, Final, Protocol

if TYPE_CHECKING:
    import asyncio
    from collections.abc import Callable

__all__ = ["GATHER_BYTES", "GATHER_S", "Gatherer", "Member"]

GATHER_BYTES: Final = 64 * 1024
"""Bytes queued for one connection that end its gathering: written at once."""

GATHER_S: Final = 0.001
"""Seconds a gathering lasts at most: the latency a burst's messages may gain."""


class Member(Protocol):
    """What gathers: the loop's deferred output (``pump``)."""

    def queued_bytes(self) -> int:
        """Bytes waiting to be written."""

    def flush(self) -> None:
        """Write what waits (or wake the writer): the gathering is over for it."""


_gatherers: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, Gatherer] = (
    weakref.WeakKeyDictionary()
)


class Gatherer:
    """The gathering of one event loop's connections (``for_loop``).

    Args:
        loop: the event loop.
        max_s: seconds a gathering lasts at most (None: ``GATHER_S``).
        clock: seconds for a gathering's age (``time.monotonic``; tests pass their own).

    Attributes:
        more: output came since the last look (set by the members' wake-ups).
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        max_s: float | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._loop = loop
        self._clock = clock
        self._max_s = GATHER_S if max_s is None else max_s
        self._members: list[Member] = []
        self._since = 0.0  # when this gathering began (``clock``)
        self._gathering = 0  # counts gatherings: a look scheduled for an earlier one is void
        self.more = False

    @classmethod
    def for_loop(cls, loop: asyncio.AbstractEventLoop) -> Gatherer:
        """The gatherer of ``loop`` (made at its first use)."""
        gatherer = _gatherers.get(loop)
        if gatherer is None:
            gatherer = _gatherers[loop] = cls(loop)
        return gatherer

    def join(self, member: Member) -> None:
        """``member`` has output: it is written at the end of the gathering (``Member.flush``)."""
        self.more = True  # also for the first: its look must wait for the publisher's turn
        if not self._members:
            self._since = self._clock()
            self._gathering += 1
            self._loop.call_soon(self._look, self._gathering, True)
        self._members.append(member)

    def release(self, member: Member) -> None:
        """``member`` has ``GATHER_BYTES`` queued: it leaves the gathering and is written now."""
        if member in self._members:
            self._members.remove(member)
        member.flush()

    def _look(self, gathering: int, first: bool) -> None:
        if gathering != self._gathering or not self._members:
            return  # an earlier gathering's, or every member was released
        if first:
            self.more = False
            full = [member for member in self._members if member.queued_bytes() >= GATHER_BYTES]
            for member in full:
                self.release(member)
            if self._members:  # the publisher's next turn tells a burst from a lone message
                self._loop.call_soon(self._look, gathering, False)
            return
        age = self._clock() - self._since
        if self.more and age < self._max_s:  # a burst
            self.more = False
            self._loop.call_later(self._max_s - age, self._end, gathering)
            return
        self._end(gathering)

    def _end(self, gathering: int) -> None:
        if gathering != self._gathering:
            return
        members, self._members = self._members, []
        self.more = False
        for member in members:
            member.flush()
