"""A burst's output gathered over turns of the event loop, then written in one go.

A publisher in the server's process that yields to the event loop after each
message (as an asyncio program does) hands each connection one message a turn.
Written as it comes, that is one system call per message and connection: most
of the cost of a burst of small messages. The ``Gatherer`` of a loop (one for
all its Foxglove connections) puts the writes off while output keeps coming:
it looks once a turn, and writes each gathering connection's frames when a
turn brought no new output, when ``GATHER_S`` have passed since the gathering
began, or when that connection has ``GATHER_BYTES`` queued. The first look of
a gathering always waits one turn more: it runs before the publisher that
caused it has had its next turn (its resumption was scheduled after the
look), so it could not tell a burst from a lone message. A lone message so
waits two turns of the loop; a message of a burst at most ``GATHER_S``.
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING, Final, Protocol

if TYPE_CHECKING:
    import asyncio

__all__ = ["GATHER_BYTES", "GATHER_S", "Gatherer", "Member"]

GATHER_BYTES: Final = 64 * 1024
"""Bytes queued for one connection that end its gathering: written at once."""

GATHER_S: Final = 0.001
"""Seconds a gathering lasts at most: the latency a burst's messages may gain."""


class Member(Protocol):
    """A connection that gathers (``driver.Wakeup``)."""

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

    Attributes:
        more: output came since the last look (set by the members' wake-ups).
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, max_s: float | None = None) -> None:
        self._loop = loop
        self._max_s = GATHER_S if max_s is None else max_s
        self._members: list[Member] = []
        self._since = 0.0  # when this gathering began (the loop's clock)
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
            self._since = self._loop.time()
            self._loop.call_soon(self._look)
        self._members.append(member)

    def _look(self) -> None:
        members = self._members
        if self.more and self._loop.time() - self._since < self._max_s:
            self.more = False
            full = [member for member in members if member.queued_bytes() >= GATHER_BYTES]
            if full:
                self._members = members = [member for member in members if member not in full]
                for member in full:
                    member.flush()
            if members:
                self._loop.call_soon(self._look)
            return
        self._members = []
        self.more = False
        for member in members:
            member.flush()
