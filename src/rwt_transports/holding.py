"""What a publishing reader waits for, and for how long: input backpressure's accounting.

A reader whose batch of frames congested an outbox waits until that outbox is
back under its low watermark (docs/limits.md, "Backpressure"). Two kinds of
outbox are waited for alike:

- another connection's (``pump.ConnectionPump``): a subscriber reading slower
  than the publishers write;
- a link's queue for the other middleware (``LinkHold``, around
  ``rwt_graph.link.Backlog``): a Zenoh network taking samples slower than the
  local publishers make them.

Each keeps its hold budget here: the seconds it held readers back in its
current episode, charged once however many readers waited together; once
spent, or once it took nothing for ``INPUT_STALL_S``, it is slow and no
longer waited for until it catches up (empties), and its own drop rules apply
(D24 for a connection, the link's byte bound for a link).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import anyio

if TYPE_CHECKING:
    from rwt_graph.link import Backlog

__all__ = ["INPUT_STALL_S", "Held", "LinkHold", "wait_for"]

INPUT_STALL_S = 1.0
"""Seconds without taking a frame, during a hold, after which a peer counts as
slow at once for input backpressure: readers stop waiting for it before its
hold budget is spent (docs/limits.md). Its queue then drops and it is closed
after ``--send-timeout`` (D24). A peer whose socket's send queue shrank
meanwhile took bytes and is not stalled (sendqueue.py)."""


class Held:
    """An outbox readers may wait for: its watermarks, hold budget and progress.

    Subclasses say what is queued (``_over_water``) and call ``_note_take``
    each time their consumer takes something; one over a socket also says what
    the kernel still holds for its peer (``_unsent_bytes``).
    """

    def __init__(self) -> None:
        self._high_water = self._low_water = 0  # bytes
        self._backlogged = False  # in the current batch's list of outboxes to wait for
        self._hold_budget = 0.0  # seconds per episode
        self._held_s = 0.0
        self._held_to = 0.0  # the time up to which holding is charged
        self._slow = False  # budget spent or stalled: not waited for until caught up
        self._takes = 0  # takes so far: the consumer's progress
        self._progress: anyio.Event | None = None  # set at the next take, for waiting readers

    def _over_water(self, *, own: bool, mark: int) -> bool:
        """Whether more than ``mark`` bytes wait (``own``: the reader's own outbox)."""
        raise NotImplementedError

    def _unsent_bytes(self) -> int | None:
        """Bytes past the outbox that its consumer has not taken yet, or None.

        A socket's send queue: progress that no take shows (sendqueue.py). None
        where that cannot be told.
        """
        return None

    def _note_take(self, caught_up: bool) -> None:
        """The consumer took something; ``caught_up``: nothing is left, the episode ends."""
        self._takes += 1
        if caught_up:
            self._held_s = 0.0
            self._slow = False
        event = self._progress
        if event is not None:
            self._progress = None
            event.set()

    def _charge_hold(self, start: float, end: float) -> None:
        """Charge the time from ``start`` to ``end`` (s) that a reader waited to the budget.

        Readers waiting together are charged once: only time after what was
        already charged counts.
        """
        start = max(start, self._held_to)
        if end > start:
            self._held_s += end - start
            self._held_to = end


async def wait_for(held: Held, *, own: bool) -> None:
    """Wait until ``held`` is under its low watermark, within its hold budget.

    Another outbox is waited for only while it is not slow: the time waited is
    charged to its budget (``--hold-budget``), and once that is spent, or it
    took nothing for ``INPUT_STALL_S``, it is slow and left to its drop rules
    until it catches up. A reader's own outbox (replies only) is waited for
    while its peer takes frames. A peer whose socket's send queue shrank during
    a wait took bytes, though no send completed (sendqueue.py): it is waited for on.
    """
    while held._over_water(own=own, mark=held._low_water):
        wait_s = INPUT_STALL_S
        if not own:
            if held._slow:
                return
            left = held._hold_budget - held._held_s
            if left <= 0:
                held._slow = True
                return
            wait_s = min(wait_s, left)
        takes = held._takes
        unsent = held._unsent_bytes()
        progress = held._progress
        if progress is None:
            progress = held._progress = anyio.Event()
        start = anyio.current_time()
        with anyio.move_on_after(wait_s):
            await progress.wait()
        if not own:
            held._charge_hold(start, anyio.current_time())
        if held._takes == takes and not _reads_meanwhile(unsent, held._unsent_bytes()):
            if not own:  # not taking: left to its drop rules
                held._slow = True
            return


def _reads_meanwhile(before: int | None, after: int | None) -> bool:
    """Whether a socket's send queue shrank: its peer read, though no send completed."""
    return before is not None and after is not None and after < before


class LinkHold(Held):
    """A link's ``Backlog`` as readers wait for it (``pump.OutboundHold`` makes one per link).

    The backlog reports each sample that goes out only while this watches it:
    from the first congestion of an episode until the backlog empties.
    """

    def __init__(self, backlog: Backlog, hold_budget_s: float) -> None:
        super().__init__()
        self.backlog = backlog
        self._high_water, self._low_water = backlog.water_marks
        self._hold_budget = hold_budget_s
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
