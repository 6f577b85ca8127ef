"""Flow control as one sans-IO object: who waits for whom, and for how long.

Input is flow-controlled (docs/limits.md, "Backpressure"): a reader whose
batch of frames pushed an outbox over its high watermark waits until that
outbox is back under its low watermark. Two kinds of outbox (``Outlet``) are
waited for alike:

- a connection's (its pump's): a subscriber reading slower than the
  publishers write;
- a link's queue for the other middleware (``rwt_graph.link.Backlog``): a
  Zenoh network taking samples slower than the local publishers make them.

``FlowControl`` holds every rule of it, for one event loop (the server owns
one): the batch being handled and the outlets it congested, the outputs
deferred to its end (the ``deferred-send`` shortcut), each outlet's watermarks
and progress, the hold budgets (``HoldAccount``), the stall rule
(``ReadingWindow``: is this consumer reading, judged on each outlet's own clock
from the moment it falls behind) and the slow verdicts with their cool-downs
(``HostCoolDowns``). Its methods take the time (``now``, seconds of
the event loop's clock) and byte counts and return decisions; the pump
(``rwt_transports.pump``, ``holding``) and the links' gates (``gates``) carry them out: pause a
socket, wait for a consumer's next take, write deferred output.

The time waited is charged to the reader being held (a publishing connection,
or a graph's link deliveries as one), however many outlets it waits for:
several slow subscribers share one budget instead of adding theirs. An outlet
is waited for only while its consumer reads, judged over ``INPUT_STALL_S`` (or
more) of being behind: a connection from the moment its outbox passes
``WATCH_SHARE`` of its high watermark, before anyone waits for it, so several
that fall behind together are judged together, not one hold after another; a
link's queue from the start of a hold. One found slow (it did not read,
or the budget ran out while it was waited for) is left to its own drop rules
(D24 for a connection, the link's byte bound for a link): a connection for
``COOL_DOWN_BUDGETS`` budgets, and so is every connection its host opens
meanwhile, whether it catches up or reconnects; a link until it catches up.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from typing import TYPE_CHECKING, Generic, NamedTuple, Protocol, TypeVar

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = [
    "COOL_DOWN_BUDGETS",
    "HOLD_REFILL",
    "INPUT_STALL_S",
    "LINK_ACCOUNTS",
    "NO_PROGRESS",
    "READING_SHARE",
    "WATCH_SHARE",
    "FlowControl",
    "Hold",
    "HoldAccount",
    "HostCoolDowns",
    "HostNames",
    "Outlet",
    "PendingOutput",
    "Progress",
    "ReadingWindow",
    "send_queue_shrank",
]

INPUT_STALL_S = 1.0
"""Seconds over which a peer that has fallen behind must show that it reads
(``READING_SHARE``), else it counts as slow at once: readers stop waiting for it
before the hold budget is spent (docs/limits.md). A connection's seconds count from
the moment its outbox passed ``WATCH_SHARE`` of its high watermark, not from the
start of a hold: a reader held for it waits only for what is left of them. Its queue
then drops and it is closed after ``--send-timeout`` (D24)."""

READING_SHARE = 1 / 16
"""Share of its backlog (outbox plus the socket's send queue, ``rwt_transports.sendqueue``) a peer
must take per ``INPUT_STALL_S`` while it is behind to count as reading. A viewer
drawing three 300 KB frames a second from a full 16 MiB connection (8 MiB queued,
4 MiB in the kernel) takes 7 %; one reading 64 KB every 0.5 s of a 10 MB/s topic,
1 %: it only looks alive."""

WATCH_SHARE = 1 / 8
"""Share of its high watermark past which a connection's outbox counts as behind:
its reading window (``INPUT_STALL_S``) starts then, and ends when the outbox is
back at this mark or with a verdict (the next starts then). 1 MiB at the default
16 MiB send buffer: a 10 MB/s topic takes a reader that only looks alive from here
to the high watermark in 0.7 s, so a publisher waits some 0.3 s for it, however
many such readers fall behind together (docs/limits.md)."""

HOLD_REFILL = 0.1
"""Seconds of hold budget a reader regains per second, up to the whole budget: over
any ``t`` seconds it is held at most ``--hold-budget`` + ``HOLD_REFILL`` x ``t``, a
tenth of the time in the long run, whoever it waits for."""

LINK_ACCOUNTS = 1024
"""Remote publishers whose hold budgets a server keeps (``FlowControl.link_account``):
past it the least recently held one's is forgotten (the publishers come from the
network, so the table is bounded)."""

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


class Progress(NamedTuple):
    """An outlet's progress at one moment (``holding.Held.progress``), bytes.

    Attributes:
        taken: what its consumer has taken so far (a count that only grows).
        backlog: what it has yet to take (outbox and send queue).
        unsent: of the backlog, what the socket's send queue holds (sendqueue.py):
            handed to the peer's connection, not yet taken; None where that
            cannot be told (then what the server has not handed over yet cannot
            be told from what the peer has not taken).
    """

    taken: int
    backlog: int
    unsent: int | None = None


NO_PROGRESS = Progress(0, 0)
"""What ``Hold.wait_s`` passes on when no reading window starts or ends (not read)."""


class ReadingWindow:
    """Whether a peer reads, judged over at least ``INPUT_STALL_S`` while it is behind.

    Args:
        taken: bytes its consumer had taken by ``now`` (a count that only grows,
            ``holding.Held.progress``).
        backlog: bytes waiting for it at ``now`` (outbox and send queue).
        now: the window's start, seconds.
        unsent: of ``backlog``, bytes in its socket's send queue (``Progress.unsent``).
    """

    def __init__(self, taken: int, backlog: int, now: float, unsent: int | None = None) -> None:
        self.taken = taken
        self.backlog = backlog
        self.unsent = unsent
        self.start = now
        self.ends = now + INPUT_STALL_S

    @classmethod
    def of(cls, progress: Progress, now: float) -> ReadingWindow:
        """The window starting at ``now`` (seconds) with the outlet's ``progress``."""
        return cls(progress.taken, progress.backlog, now, progress.unsent)

    def reading(self, taken: int, backlog: int, now: float, unsent: int | None = None) -> bool:
        """Whether the peer took ``READING_SHARE`` per ``INPUT_STALL_S`` since the start.

        ``taken``, ``backlog`` and ``unsent`` as at the start, at ``now`` (at or
        after ``ends``). The share is of the larger backlog, the start's or this
        one, so a window that started when the peer fell behind asks the rate its
        backlog has reached since.

        A peer that took at least half of what reached its socket in the window
        (what its send queue held at the start, and what the server handed to it
        since; something) reads, whatever the share: its backlog waits in the
        server, whose writer fell behind (its event loop busy with a link's burst,
        or short of CPU), not in the peer (D61). Known only where the send queue
        can be read. A window in which nothing reached it is judged by the share.
        """
        elapsed = max(now - self.start, INPUT_STALL_S)
        share = READING_SHARE * elapsed / INPUT_STALL_S
        if taken - self.taken >= max(self.backlog, backlog) * share:
            return True
        if self.unsent is None or unsent is None:
            return False
        offered = (taken + unsent) - (self.taken + self.unsent) + self.unsent
        return offered > 0 and unsent * 2 <= offered


def send_queue_shrank(before: int | None, after: int | None) -> bool:
    """Whether a socket's send queue shrank: its peer read, though no send completed.

    ``before``, ``after``: the queue's bytes (None where it cannot be read).
    """
    return before is not None and after is not None and after < before


class HostNames(Protocol):
    """How peers group into hosts (the server's ``HostPrefixes``, ``rwt_transports.admission``)."""

    def host_of(self, peer: str) -> str:
        """The host a peer address (``host:port``, ``stdio``, ``memory``) counts as."""


class HostCoolDowns:
    """Until when each host's connections are not waited for, after one was found slow.

    Hosts are grouped as for the connection shares (``HostNames``: the server's
    ``--host-prefix-v4`` and ``-v6``). Memory: one entry per host found slow within
    its cool-down; expired ones go at the next verdict.

    Args:
        hosts: the server's host grouping.
    """

    def __init__(self, hosts: HostNames) -> None:
        self._hosts = hosts
        self._until: dict[str, float] = {}

    def host(self, peer: str) -> str:
        """The host a peer address (``host:port``, ``stdio``, ``memory``) counts as."""
        return self._hosts.host_of(peer)

    def until(self, host: str) -> float:
        """The time until which ``host``'s new connections are not waited for (-inf: none)."""
        return self._until.get(host, -math.inf)

    def cool(self, host: str, until: float, now: float) -> None:
        """``host`` is not waited for until ``until`` (s); drop the entries expired at ``now``."""
        self._until = {h: t for h, t in self._until.items() if t > now}
        self._until[host] = max(until, self.until(host))

    def __len__(self) -> int:
        """Hosts remembered (within their cool-down, or expired since the last verdict)."""
        return len(self._until)


class Outlet:
    """An outbox readers may wait for, as flow control sees it: marks, progress, verdict.

    A connection's (its pump) or a link's queue (``holding.LinkHold``). A
    connection found slow is not waited for during a cool-down
    (``cool_down_s``), nor is its host; a link (``cool_down_s`` None) until it
    catches up.

    Attributes:
        high_water: bytes past which it congests a reader's batch.
        low_water: bytes under which a reader held for it goes on.
        watch_water: bytes past which its reading window starts before any hold
            (a connection: ``WATCH_SHARE`` of ``high_water``); a link's starts
            with a hold.
        congested: in the current batch's list of outlets to wait for.
        takes: its consumer's takes so far: its progress.
        window: the reading window since it fell behind (None: not behind), one
            for every reader held for it.
        counts_taken: its progress counts what its consumer took, so its window
            runs while it is behind, across holds; else (a link's queue, whose
            progress is its backlog's shrinking) a window lasts one hold.
    """

    counts_taken = False

    def __init__(self, high_water: int = 0, low_water: int = 0) -> None:
        self.high_water = high_water
        self.low_water = low_water
        self.watch_water = high_water
        self.congested = False
        self.window: ReadingWindow | None = None
        self.takes = 0
        self.cool_down_s: float | None = None  # None: slow until caught up (a link)
        self.host: str | None = None  # its host, for the cool-downs (a connection of a server)
        self._slow = False  # a link found slow, until caught up
        self._slow_until = -math.inf  # a connection found slow (or its host): until then

    def is_slow(self, now: float) -> bool:
        """Whether readers leave it to its drop rules at ``now`` instead of waiting."""
        return self._slow or now < self._slow_until

    def took(self, caught_up: bool) -> None:
        """Its consumer took something (``caught_up``: nothing is left)."""
        self.takes += 1
        if caught_up:
            self._slow = False  # a link; a connection stays slow until its cool-down ends


class PendingOutput(Protocol):
    """A connection whose output waits for the end of the batch (the ``deferred-send`` path)."""

    def flush_deferred(self) -> None:
        """Write what it queued (or wake its writer)."""


OutletT = TypeVar("OutletT", bound=Outlet)


class Hold(Generic[OutletT]):
    """One held reader waiting for one congested outlet: the stall rule and the budget.

    ``FlowControl.hold`` makes it. The caller (the pump's ``holding.wait_for``)
    runs the hold loop: it asks ``wait_s`` how long to wait for the consumer's
    next take, waits, and reports the time it waited (``waited``), until
    ``wait_s`` says go on. The outlet is found slow when its consumer did not take
    ``READING_SHARE`` of its backlog in its reading window (the outlet's, which may
    have started before the hold: ``WATCH_SHARE``), or when the reader's budget ran
    out while it was waited for.
    """

    def __init__(self, flow: FlowControl[OutletT], outlet: OutletT, account: HoldAccount) -> None:
        self._flow = flow
        self._outlet = outlet
        self._account = account
        self._waited = False

    def needs_progress(self, now: float) -> bool:
        """Whether ``next_wait`` at ``now`` needs the outlet's progress (a window starts, ends)."""
        window = self._outlet.window
        return window is None or now >= window.ends

    def next_wait(self, now: float, progress: Progress) -> float | None:
        """Seconds to wait for the consumer's next take at ``now``, or None: stop waiting.

        Args:
            now: the time, seconds.
            progress: what its consumer has taken so far and has yet to take,
                ``holding.Held.progress``; read only when ``needs_progress`` said so.
        """
        outlet = self._outlet
        window = outlet.window
        if window is None:
            window = outlet.window = ReadingWindow.of(progress, now)
        elif now >= window.ends:
            if not window.reading(progress.taken, progress.backlog, now, progress.unsent):
                self._flow.found_slow(outlet, now)
                return None
            window = outlet.window = ReadingWindow.of(progress, now)
        left = self._account.left(now)
        if left <= 0:
            if self._waited:  # it kept the reader until the budget ran out
                self._flow.found_slow(outlet, now)
            return None
        return min(window.ends - now, left)

    def wait_s(self, now: float, over_low: bool, progress: Callable[[], Progress]) -> float | None:
        """The hold loop's one decision at ``now``: seconds to wait, or None: go on.

        Args:
            now: monotonic seconds.
            over_low: whether the outlet is over its low watermark now.
            progress: the outlet's bytes taken so far and yet to be taken (asked
                only when a reading window starts or ends: ``needs_progress``).

        The caller waits that long or until the consumer's next take, whichever
        is first, then reports the time (``waited``) and asks again.
        """
        wait = None
        if over_low:
            wait = self.next_wait(now, progress() if self.needs_progress(now) else NO_PROGRESS)
        if wait is None and not self._outlet.counts_taken:
            self._outlet.window = None  # its window lasts one hold
        return wait

    def waited(self, start: float, end: float) -> None:
        """The reader waited from ``start`` to ``end`` (s): charge its budget."""
        self._account.charge(start, end)
        self._waited = True


class FlowControl(Generic[OutletT]):
    """The flow control of one event loop's connections and links (see the module text).

    Used on that loop only; sans-IO: every method takes the time and returns.

    Args:
        hold_budget_s: seconds a link's deliveries of one remote publisher may be
            held (``--hold-budget``, ``link_account``), and those of no known
            publisher, all links as one reader (``links``).
        cool_downs: the server's per-host cool-downs; None: a connection's
            cool-down ends with it.
    """

    def __init__(self, hold_budget_s: float = 0.0, cool_downs: HostCoolDowns | None = None) -> None:
        self.links = HoldAccount(hold_budget_s)
        """The hold budget of the links' deliveries (``InflowGate``) of no known publisher."""
        self._publishers: OrderedDict[str, HoldAccount] = OrderedDict()
        self.cool_downs = cool_downs
        self.in_batch = False
        """A reader (or a link's deliveries) is handling a batch, and flushes at its end."""
        self._congested: list[OutletT] = []  # over the high watermark in this batch
        self._deferred: list[PendingOutput] = []  # output to write at the batch's end

    def link_account(self, publisher: str | None) -> HoldAccount:
        """The hold budget a link's deliveries of ``publisher``'s samples are charged to.

        Each remote publisher (a participant a link mirrors) has its own, of the
        size a local publisher's reader has (``--hold-budget``, as ``links``), as
        if it were held at its source (D61); None (no publisher known): ``links``.
        At most ``LINK_ACCOUNTS`` are kept, the least recently used forgotten.
        """
        if publisher is None:
            return self.links
        account = self._publishers.get(publisher)
        if account is None:
            account = self._publishers[publisher] = HoldAccount(self.links.budget_s)
            if len(self._publishers) > LINK_ACCOUNTS:
                self._publishers.popitem(last=False)
        else:
            self._publishers.move_to_end(publisher)
        return account

    # -- a batch and who congested it

    def begin(self) -> None:
        """A batch starts: congestion is noted and output deferred until ``end``."""
        self.in_batch = True

    def end(self) -> None:
        """The batch ended (the caller writes out what was deferred: ``take_deferred``)."""
        self.in_batch = False

    def congests(self, outlet: OutletT, queued: int) -> bool:
        """Whether ``queued`` bytes in ``outlet`` congest the current batch (not noted yet).

        Cheap, asked for every output; ``note_congested`` then decides.
        """
        return self.in_batch and not outlet.congested and queued > outlet.high_water

    def note_congested(self, outlet: OutletT, now: float) -> None:
        """``outlet`` went over its high watermark in this batch: the reader is to wait for it.

        An outlet found slow is not waited for.
        """
        if self.in_batch and not outlet.congested and not outlet.is_slow(now):
            outlet.congested = True
            self._congested.append(outlet)

    def has_congested(self) -> bool:
        """Whether an outlet went over its high watermark since the last ``take_congested``."""
        return bool(self._congested)

    def take_congested(self) -> list[OutletT]:
        """The outlets pushed over their high watermark since the last take, for the reader."""
        congested = self._congested
        if congested:
            self._congested = []
            for outlet in congested:
                outlet.congested = False
        return congested

    # -- output deferred to the end of the batch (the ``deferred-send`` shortcut)

    def defer(self, output: PendingOutput) -> None:
        """Leave ``output`` for the end of the batch (``take_deferred``)."""
        self._deferred.append(output)

    def needs_flush_callback(self) -> bool:
        """Whether a deferral now needs a flush of its own: no batch ends to flush it.

        True for the first deferral outside a batch (in-process publishers,
        timers, service tasks): the caller schedules one flush on its loop.
        """
        return not self._deferred and not self.in_batch

    def take_deferred(self) -> list[PendingOutput]:
        """The outputs deferred since the last take, in order; the caller writes them."""
        deferred = self._deferred
        if deferred:
            self._deferred = []
        return deferred

    # -- outlets and verdicts

    def open_connection(
        self, outlet: OutletT, peer: str, budget_s: float, water_marks: tuple[int, int]
    ) -> HoldAccount:
        """A connection starts: its outlet's marks and cool-down; returns its hold budget.

        Args:
            outlet: the connection's outlet.
            peer: its peer address (``host:port``, ``stdio``, ``memory``).
            budget_s: its hold budget as a reader (``--hold-budget``), seconds.
            water_marks: its outbox's (high, low) watermarks, bytes; its reading
                window starts past ``WATCH_SHARE`` of the high one.

        Returns:
            the account its reader is charged for every outlet it waits for. A
            reconnection of a host found slow within its cool-down starts slow.
        """
        outlet.high_water, outlet.low_water = water_marks
        outlet.watch_water = int(outlet.high_water * WATCH_SHARE)
        outlet.cool_down_s = COOL_DOWN_BUDGETS * budget_s
        cool_downs = self.cool_downs
        if cool_downs is not None:
            outlet.host = cool_downs.host(peer)
            outlet._slow_until = cool_downs.until(outlet.host)
        return HoldAccount(budget_s)

    def found_slow(self, outlet: OutletT, now: float) -> None:
        """``outlet`` did not read, or a reader's budget ran out waiting for it, at ``now``.

        A connection is not waited for during its cool-down, nor its host's
        connections opened meanwhile; a link until it catches up.
        """
        outlet.window = None  # judged: the next verdict is on what comes after
        cool_down_s = outlet.cool_down_s
        if cool_down_s is None:
            outlet._slow = True
            return
        outlet._slow_until = now + cool_down_s
        if self.cool_downs is not None and outlet.host is not None:
            self.cool_downs.cool(outlet.host, outlet._slow_until, now)

    def hold(
        self, outlet: OutletT, account: HoldAccount | None, now: float
    ) -> Hold[OutletT] | None:
        """A reader charged to ``account`` is to wait for ``outlet`` (another's) at ``now``.

        Returns:
            the hold that says how long to wait, or None: ``outlet`` is not
            waited for (found slow, or no account to charge).
        """
        if account is None or outlet.is_slow(now):
            return None
        return Hold(self, outlet, account)
