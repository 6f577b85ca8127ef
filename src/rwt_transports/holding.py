"""Holds carried out: a reader waits for an outlet's consumer, as flow control decides.

A reader whose batch of frames congested an outbox waits until that outbox is
back under its low watermark (docs/limits.md, "Backpressure"). Whether to wait,
how long and who is slow is ``rwt_protocol.runtime.flow.FlowControl``'s to decide (sans-IO); this
module does the waiting on the event loop: an outlet (``Held``: a connection's
pump, or a link's queue, ``LinkHold``) tells what waits in it and wakes the
readers waiting for it at each take of its consumer.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import anyio

from rwt_protocol.runtime.flow import INPUT_STALL_S, Outlet, Progress, send_queue_shrank

if TYPE_CHECKING:
    from rwt_graph.link import Backlog
    from rwt_protocol.runtime.flow import FlowControl, HoldAccount

__all__ = ["Held", "LinkHold", "wait_for"]


class Held(Outlet):
    """An outlet readers wait for, with the I/O that tells its state and its progress.

    Subclasses say what is queued (``over_water``, ``backlog_bytes``) and call
    ``note_take`` each time their consumer takes something; one over a socket
    also says what the kernel still holds for its peer (``unsent_bytes``), and
    one that counts what its consumer took says so (``progress``).
    """

    def __init__(self) -> None:
        super().__init__()
        self._progress: anyio.Event | None = None  # set at the next take, for waiting readers

    def over_water(self, *, own: bool, mark: int) -> bool:
        """Whether more than ``mark`` bytes wait (``own``: the reader's own outbox)."""
        raise NotImplementedError

    def backlog_bytes(self) -> int:
        """Bytes its consumer has yet to take: queued, and in the socket's send queue."""
        raise NotImplementedError

    def progress(self) -> Progress:
        """Bytes its consumer has taken so far (a count that only grows) and bytes left.

        By default the count is the backlog's shrinking (minus the backlog): right
        only while nothing is added, so such an outlet's reading window lasts one
        hold (``counts_taken`` False); a connection counts what it sent, and says
        what its socket's send queue holds.
        """
        backlog = self.backlog_bytes()
        return Progress(-backlog, backlog)

    def unsent_bytes(self) -> int | None:
        """Bytes past the outbox that its consumer has not taken yet, or None.

        A socket's send queue: progress that no take shows (sendqueue.py). None
        where that cannot be told.
        """
        return None

    def note_take(self, caught_up: bool) -> None:
        """The consumer took something; ``caught_up``: nothing is left. Wakes waiting readers."""
        self.took(caught_up)
        event = self._progress
        if event is not None:
            self._progress = None
            event.set()

    async def next_take(self, wait_s: float) -> None:
        """Wait for the consumer's next take, at most ``wait_s`` seconds."""
        progress = self._progress
        if progress is None:
            progress = self._progress = anyio.Event()
        with anyio.move_on_after(wait_s):
            await progress.wait()


async def wait_for(
    flow: FlowControl[Held], held: Held, *, own: bool, account: HoldAccount | None
) -> None:
    """Wait until ``held`` is under its low watermark, as long as ``flow`` says to.

    Another outbox is waited for while ``flow``'s hold says so (it reads, and
    ``account``, the held reader's budget, has time left), the time waited
    charged to ``account``: but for a wait after which its socket's send queue is
    empty, where it can be read: its peer took all the server gave it, and what
    waits is the server's own (its writer behind its deliveries: a link's burst,
    a process short of CPU), not the peer's (D61). A reader's own outbox
    (replies only, never dropped; ``account`` unused) is waited for while its
    peer takes frames, or its socket's send queue shrinks.
    """
    if own:
        await _wait_for_own(held)
        return
    clock = anyio.current_time
    now = clock()
    hold = flow.hold(held, account, now)
    if hold is None:
        return
    while True:
        over_low = held.over_water(own=False, mark=held.low_water)
        wait_s = hold.wait_s(now, over_low, held.progress)
        if wait_s is None:
            return
        await held.next_take(wait_s)
        end = clock()
        if held.unsent_bytes() != 0:  # None (not known), or its peer is behind
            hold.waited(now, end)
        now = end


async def _wait_for_own(held: Held) -> None:
    """Wait while the reader's own outbox is over its low watermark and its peer takes."""
    while held.over_water(own=True, mark=held.low_water):
        takes = held.takes
        unsent = held.unsent_bytes()
        await held.next_take(INPUT_STALL_S)
        if held.takes == takes and not send_queue_shrank(unsent, held.unsent_bytes()):
            return


class LinkHold(Held):
    """A link's ``Backlog`` as readers wait for it (``gates.OutboundHold`` makes one per link).

    The backlog reports each sample that goes out only while this watches it:
    from the first congestion of an episode until the backlog empties. Found
    slow, it is not waited for until it empties.
    """

    def __init__(self, backlog: Backlog) -> None:
        super().__init__()
        self.backlog = backlog
        self.high_water, self.low_water = backlog.water_marks
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
        self.note_take(caught_up)

    def over_water(self, *, own: bool, mark: int) -> bool:
        """Whether more than ``mark`` bytes wait in the link's queue."""
        return self.backlog.queued_bytes > mark

    def backlog_bytes(self) -> int:
        """Bytes waiting in the link's queue."""
        return self.backlog.queued_bytes
