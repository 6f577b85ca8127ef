"""What a publishing reader waits for, and for how long: input backpressure's accounting.

A reader whose batch of frames congested an outbox waits until that outbox is
back under its low watermark (docs/limits.md, "Backpressure"). Two kinds of
outbox are waited for alike:

- another connection's (``pump.ConnectionPump``): a subscriber reading slower
  than the publishers write;
- a link's queue for the other middleware (``LinkHold``, around
  ``rwt_graph.link.Backlog``): a Zenoh network taking samples slower than the
  local publishers make them.

The time waited is charged to the reader being held (``HoldAccount``: a
publishing connection, or a graph's link deliveries as one), however many
outboxes it waits for: several slow subscribers share one budget instead of
adding theirs. An outbox is waited for only while its consumer reads
(``ReadingWindow``); one found slow (it did not read, or the budget ran out
while it was waited for) is left to its own drop rules (D24 for a connection,
the link's byte bound for a link): a connection for ``COOL_DOWN_BUDGETS``
budgets, and so is every connection its host opens meanwhile
(``HostCoolDowns``), whether it catches up or reconnects; a link until it
catches up.

``HoldAccount``, ``ReadingWindow`` and ``HostCoolDowns`` are sans-IO: they take
the time (``now``, seconds of the event loop's clock) and byte counts as
arguments.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import anyio

from .shares import HostPrefixes, address_of

if TYPE_CHECKING:
    from rwt_graph.link import Backlog

__all__ = [
    "COOL_DOWN_BUDGETS",
    "HOLD_REFILL",
    "INPUT_STALL_S",
    "READING_SHARE",
    "Held",
    "HoldAccount",
    "HostCoolDowns",
    "LinkHold",
    "ReadingWindow",
    "wait_for",
]

INPUT_STALL_S = 1.0
"""Seconds of a hold over which a peer must show that it reads (``READING_SHARE``),
else it counts as slow at once: readers stop waiting for it before the hold
budget is spent (docs/limits.md). Its queue then drops and it is closed after
``--send-timeout`` (D24)."""

READING_SHARE = 1 / 16
"""Share of its backlog (outbox plus the socket's send queue, sendqueue.py) a peer
must take in each ``INPUT_STALL_S`` of a hold to count as reading. A viewer
drawing three 300 KB frames a second from a full 16 MiB connection (8 MiB queued,
4 MiB in the kernel) takes 7 %; one reading 64 KB every 0.5 s of a 10 MB/s topic,
1 %: it only looks alive."""

HOLD_REFILL = 0.1
"""Seconds of hold budget a reader regains per second, up to the whole budget: over
any ``t`` seconds it is held at most ``--hold-budget`` + ``HOLD_REFILL`` x ``t``, a
tenth of the time in the long run, whoever it waits for."""

COOL_DOWN_BUDGETS = 20.0
"""Hold budgets' worth of seconds a connection found slow, and every connection its
host opens meanwhile, is not waited for (100 s at the default 5 s budget): one
host can hold a publisher back for at most one budget in 21."""


class HoldAccount:
    """The hold budget of one reader being held: what it has left, charged once per second.

    A token bucket: ``budget_s`` seconds, spent by each second the reader waits
    (whatever it waits for), regained at ``HOLD_REFILL`` a second.

    Args:
        budget_s: the whole budget, seconds (``--hold-budget``); 0: never held.
    """

    def __init__(self, budget_s: float) -> None:
        self.budget_s = budget_s
        self._spent = 0.0  # seconds, as of ``_at``
        self._at = -math.inf  # the time ``_spent`` was last settled
        self._charged_to = -math.inf  # the time up to which waiting is charged

    def _settle(self, now: float) -> None:
        if now > self._at:
            if self._spent > 0:
                self._spent = max(0.0, self._spent - (now - self._at) * HOLD_REFILL)
            self._at = now

    def left(self, now: float) -> float:
        """Seconds the reader may still be held at ``now`` (0 or more)."""
        self._settle(now)
        return max(0.0, self.budget_s - self._spent)

    def charge(self, start: float, end: float) -> None:
        """Charge the wait from ``start`` to ``end`` (s).

        Waits that overlap (link deliveries waiting in several tasks) are
        charged once: only time after what was already charged counts.
        """
        start = max(start, self._charged_to)
        if end > start:
            self._settle(end)
            self._spent += end - start
            self._charged_to = end


class ReadingWindow:
    """Whether a peer reads, judged over ``INPUT_STALL_S`` of a hold.

    Args:
        backlog: bytes waiting for the peer at ``now`` (outbox and send queue).
        now: the window's start, seconds.
    """

    def __init__(self, backlog: int, now: float) -> None:
        self.backlog = backlog
        self.ends = now + INPUT_STALL_S

    def reading(self, backlog: int) -> bool:
        """Whether the peer took ``READING_SHARE`` of the window's backlog, now ``backlog``."""
        return self.backlog - backlog >= self.backlog * READING_SHARE


class HostCoolDowns:
    """Until when each host's connections are not waited for, after one was found slow.

    Hosts are grouped as for the connection shares (``shares.HostPrefixes``).
    Memory: one entry per host found slow within its cool-down; expired ones go
    at the next verdict.

    Args:
        hosts: the server's host grouping.
    """

    def __init__(self, hosts: HostPrefixes) -> None:
        self._hosts = hosts
        self._until: dict[str, float] = {}

    def host(self, peer: str) -> str:
        """The host a peer address (``host:port``, ``stdio``, ``memory``) counts as."""
        return self._hosts.host(address_of(peer))

    def until(self, host: str) -> float:
        """The time until which ``host``'s new connections are not waited for (-inf: none)."""
        return self._until.get(host, -math.inf)

    def cool(self, host: str, until: float, now: float) -> None:
        """``host`` is not waited for until ``until`` (s); drop the entries expired at ``now``."""
        self._until = {h: t for h, t in self._until.items() if t > now}
        self._until[host] = max(until, self.until(host))


class Held:
    """An outbox readers may wait for: its watermarks, backlog and progress.

    Subclasses say what is queued (``_over_water``, ``_backlog_bytes``) and call
    ``_note_take`` each time their consumer takes something; one over a socket
    also says what the kernel still holds for its peer (``_unsent_bytes``).
    """

    def __init__(self) -> None:
        self._high_water = self._low_water = 0  # bytes
        self._backlogged = False  # in the current batch's list of outboxes to wait for
        self._slow = False  # found slow: not waited for until caught up (``_is_slow``)
        self._takes = 0  # takes so far: the consumer's progress
        self._progress: anyio.Event | None = None  # set at the next take, for waiting readers

    def _over_water(self, *, own: bool, mark: int) -> bool:
        """Whether more than ``mark`` bytes wait (``own``: the reader's own outbox)."""
        raise NotImplementedError

    def _backlog_bytes(self) -> int:
        """Bytes its consumer has yet to take: queued, and in the socket's send queue."""
        raise NotImplementedError

    def _unsent_bytes(self) -> int | None:
        """Bytes past the outbox that its consumer has not taken yet, or None.

        A socket's send queue: progress that no take shows (sendqueue.py). None
        where that cannot be told.
        """
        return None

    def _is_slow(self, now: float) -> bool:
        """Whether readers leave it to its drop rules at ``now`` instead of waiting."""
        return self._slow

    def _found_slow(self, now: float) -> None:
        """It did not read, or the reader's budget ran out waiting for it, at ``now``."""
        self._slow = True

    def _note_take(self, caught_up: bool) -> None:
        """The consumer took something; ``caught_up``: nothing is left."""
        self._takes += 1
        if caught_up:
            self._slow = False
        event = self._progress
        if event is not None:
            self._progress = None
            event.set()

    async def _next_take(self, wait_s: float) -> None:
        """Wait for the consumer's next take, at most ``wait_s`` seconds."""
        progress = self._progress
        if progress is None:
            progress = self._progress = anyio.Event()
        with anyio.move_on_after(wait_s):
            await progress.wait()


async def wait_for(held: Held, *, own: bool, account: HoldAccount | None) -> None:
    """Wait until ``held`` is under its low watermark, while it reads and budget is left.

    Another outbox is waited for only while it is not slow, its consumer takes
    ``READING_SHARE`` of its backlog in each ``INPUT_STALL_S`` and ``account``
    (the held reader's, ``--hold-budget``) has time left; the time waited is
    charged to ``account``. When its consumer did not read, or the budget ran
    out while it was waited for, it is found slow (``Held._found_slow``). A
    reader's own outbox (replies only, never dropped; ``account`` unused) is
    waited for while its peer takes frames, or its socket's send queue shrinks.
    """
    if own:
        await _wait_for_own(held)
        return
    clock = anyio.current_time
    now = clock()
    if account is None or held._is_slow(now):
        return
    window = ReadingWindow(held._backlog_bytes(), now)
    waited = False
    while held._over_water(own=False, mark=held._low_water):
        if now >= window.ends:
            backlog = held._backlog_bytes()
            if not window.reading(backlog):
                held._found_slow(now)
                return
            window = ReadingWindow(backlog, now)
        left = account.left(now)
        if left <= 0:
            if waited:  # it kept the reader until the budget ran out
                held._found_slow(now)
            return
        await held._next_take(min(window.ends - now, left))
        end = clock()
        account.charge(now, end)
        now, waited = end, True


async def _wait_for_own(held: Held) -> None:
    """Wait while the reader's own outbox is over its low watermark and its peer takes."""
    while held._over_water(own=True, mark=held._low_water):
        takes = held._takes
        unsent = held._unsent_bytes()
        await held._next_take(INPUT_STALL_S)
        if held._takes == takes and not _reads_meanwhile(unsent, held._unsent_bytes()):
            return


def _reads_meanwhile(before: int | None, after: int | None) -> bool:
    """Whether a socket's send queue shrank: its peer read, though no send completed."""
    return before is not None and after is not None and after < before


class LinkHold(Held):
    """A link's ``Backlog`` as readers wait for it (``pump.OutboundHold`` makes one per link).

    The backlog reports each sample that goes out only while this watches it:
    from the first congestion of an episode until the backlog empties. Found
    slow, it is not waited for until it empties.
    """

    def __init__(self, backlog: Backlog) -> None:
        super().__init__()
        self.backlog = backlog
        self._high_water, self._low_water = backlog.water_marks
        self.watching = False

    def watch(self) -> None:
        """Follow the backlog's progress (on its congestion) until it empties."""
        if not self.watching:
            self.watching = True
            self.backlog.watch(self._on_take)

    def _on_take(self, caught_up: bool) -> None:
        if caught_up:
            self.watching = False
            self.backlog.watch(None)
        self._note_take(caught_up)

    def _over_water(self, *, own: bool, mark: int) -> bool:
        return self.backlog.queued_bytes > mark

    def _backlog_bytes(self) -> int:
        return self.backlog.queued_bytes
