"""One server-wide memory budget for what clients make the server hold (D44, docs/limits.md).

Each connection is bounded on its own (``--send-buffer-limit``, ``--max-message-size``,
the png backlog, one asset file), but with thousands of connections the sum of
those bounds is gigabytes: 30 Foxglove clients that each fetched a 10 MB asset
and never read held 357 MB, and nothing bounded the total. ``MemoryBudget`` is the
bound on the total (``--memory-budget``). Charged to it: every connection's
outbox (topic messages, replies, asset files) and what its transport took from it
and is still writing, its png messages waiting to be deflated, a WebRTC peer's
input not read yet (each connection's ``MemoryAccount``), and the incomplete
messages and frames of every connection (``FragmentBudget`` is counted in it).

The per-client bounds stay as they are, inside the budget. While it is full
(charged past its ``limit``, or something was refused for want of room), the
rule takes from the clients that do not read, the slow-consumer rule (D24):

- a connection that has held something for ``PRESSURE_STALL_S`` without its
  transport taking anything from it (counted from its last take, or from the
  first sweep that saw it holding) is *stalled*: it keeps only its newest topic
  message, the oldest dropped first;
- over the limit, any other connection keeps at most the larger of its share
  (``limit`` over the connections holding anything) and ``READER_KEEP`` of its
  send buffer: a reader is held at half its buffer by input backpressure
  (docs/limits.md), so it loses nothing it would not lose alone, and a
  connection that stops reading is cut within ``PRESSURE_STALL_S``;
- a connection holding more than ``PRESSURE_FLOOR_BYTES`` that takes nothing for
  ``--send-timeout`` is closed as a slow consumer, whatever it holds (replies,
  an asset file): replies are never dropped, so this is how they are freed;
- a Foxglove asset file, which would grow the total, is refused with a text
  naming ``--memory-budget`` (``refusal``) until there is room.

A reader's replies and every client's input are never refused or dropped for
the budget: input (incomplete messages, frames still arriving, WebRTC input not
read yet) is counted, within its own bounds, so that the outboxes of clients
that do not read are cut sooner. So the total stays within the limit, but for
the backlogs of connections that took something within ``PRESSURE_STALL_S``
(each within ``READER_KEEP`` of its send buffer), the newest message of each,
input, and the replies of those about to be closed.

The rule is applied when messages come for a connection, and to every
connection by a sweep, one pass over those holding anything, at most once per
``PRESSURE_SWEEP_S`` and only while the budget is full: whenever a session
queues or takes output, and on a timer of one session (the ``sweeper``) while
nothing else happens. Time comes from the callers (sans-IO): the latest any
session gave (``clock``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = [
    "DEFAULT_MEMORY_BUDGET",
    "MEMORY_BUDGET_OPTION",
    "PRESSURE_FLOOR_BYTES",
    "PRESSURE_STALL_S",
    "PRESSURE_SWEEP_S",
    "READER_KEEP",
    "MemoryAccount",
    "MemoryBudget",
]

DEFAULT_MEMORY_BUDGET: Final = 1024 * 1024 * 1024
"""Default ``--memory-budget``, bytes: 1 GiB, 64 connections' whole send buffers (16 MiB)."""

MEMORY_BUDGET_OPTION: Final = "--memory-budget"
"""The option that sets the budget, named to a client that meets it."""

PRESSURE_SWEEP_S: Final = 1.0
"""Seconds between two passes over the connections while the budget is full."""

PRESSURE_STALL_S: Final = 1.0
"""Seconds a connection holds something without its transport taking anything before
it counts as not reading (stalled) for the budget (module text)."""

READER_KEEP: Final = 0.75
"""Share of its send buffer a connection that reads keeps while the budget is over its
limit: its high watermark (half), where input backpressure holds its publishers, and
a quarter for what comes before the hold takes effect (a read slice of a publisher)."""

PRESSURE_FLOOR_BYTES: Final = 64 * 1024
"""Bytes a connection may hold while the budget is full without being watched: past
them, taking nothing for ``--send-timeout`` closes it (slow consumer)."""


class MemoryBudget:
    """The bytes every connection of one server (one process) may make it hold together.

    Args:
        limit: bytes, over every connection (``--memory-budget``).

    Attributes:
        limit: the budget, bytes.
        used: bytes charged now (connections' accounts and ``take``).
        wanted: something was refused for want of room since the last sweep.
        now: the latest monotonic time a session gave (``clock``), seconds.
        next_sweep: when the next sweep may run, monotonic seconds.
        sweeper: the session whose timer runs the next sweep while the budget is
            full (set and cleared by it), or None.
    """

    __slots__ = ("_holders", "limit", "next_sweep", "now", "sweeper", "used", "wanted")

    def __init__(self, limit: int = DEFAULT_MEMORY_BUDGET) -> None:
        self.limit = limit
        self.used = 0
        self.wanted = False
        self.now = float("-inf")
        self.sweeper: object | None = None
        self._holders: set[MemoryAccount] = set()  # the accounts holding anything
        self.next_sweep = float("-inf")

    def clock(self, now: float) -> None:
        """A session's time, monotonic seconds: the budget's clock goes forward to it."""
        self.now = max(self.now, now)

    @property
    def pressed(self) -> bool:
        """Whether the budget is full: charged past its limit, or a charge was refused."""
        return self.used > self.limit or self.wanted

    @property
    def share(self) -> int:
        """The budget over the connections holding anything, bytes."""
        return self.limit // max(1, len(self._holders))

    @property
    def holders(self) -> int:
        """Connections holding anything now."""
        return len(self._holders)

    def account(self, on_pressure: Callable[[float], None] | None = None) -> MemoryAccount:
        """A connection's account; ``on_pressure(now)`` is called by ``sweep`` (module text)."""
        return MemoryAccount(self, on_pressure)

    def fits(self, cost: int) -> bool:
        """Whether ``cost`` more bytes stay within the limit; notes a refusal when not."""
        if self.used + cost <= self.limit:
            return True
        self.wanted = True
        return False

    def hold(self, cost: int) -> None:
        """Count ``cost`` bytes held by no connection's account, never refused.

        The incomplete messages and frames still arriving (``FragmentBudget``,
        bounded by ``--max-fragment-memory``) are counted so: a sender's input.
        """
        self.used += cost

    def release(self, cost: int) -> None:
        """Count ``cost`` bytes of ``hold`` fewer."""
        self.used -= cost

    def refusal(self, what: str) -> str:
        """The text a client gets for ``what`` (``message 'ID'``, a URI) refused for room."""
        return (
            f"{what} refused: the server's memory budget is full ({self.used} of {self.limit} "
            f"bytes held for its clients, {MEMORY_BUDGET_OPTION}): try again later"
        )

    def sweep(self, now: float) -> None:
        """While the budget is full, tell each connection holding anything (``on_pressure``).

        At most once per ``PRESSURE_SWEEP_S``; ``now`` is monotonic seconds. A
        connection seen holding for the first time is timed from here (``stalled``).
        """
        self.clock(now)
        if now < self.next_sweep or not self.pressed:
            return
        self.next_sweep = now + PRESSURE_SWEEP_S
        self.wanted = False
        for account in list(self._holders):
            if account.idle_since is None:
                account.idle_since = self.now  # (a fresh clock: it lags between sweeps)
            if account.on_pressure is not None:
                account.on_pressure(now)


class MemoryAccount:
    """What one connection holds of a ``MemoryBudget``, and whether it reads.

    Args:
        budget: the server's budget.
        on_pressure: called with ``now`` by the budget's sweep while it is full.

    Attributes:
        held: bytes this connection holds now.
        idle_since: when its transport last took something, or a sweep first saw
            it holding something, on the budget's clock (seconds); None: neither
            since it began to hold.
    """

    __slots__ = ("budget", "closed", "held", "idle_since", "on_pressure")

    def __init__(
        self, budget: MemoryBudget, on_pressure: Callable[[float], None] | None = None
    ) -> None:
        self.budget = budget
        self.held = 0
        self.on_pressure = on_pressure
        self.closed = False
        self.idle_since: float | None = None

    def charge(self, delta: int) -> None:
        """Add ``delta`` bytes (negative: they were freed); nothing once closed."""
        if self.closed:
            return
        budget = self.budget
        before = self.held
        self.held = before + delta
        budget.used += delta
        if not before:
            if self.held:
                budget._holders.add(self)
                self.idle_since = None  # the budget's clock may lag: a sweep starts it
        elif not self.held:
            budget._holders.discard(self)

    def took(self, now: float) -> None:
        """Its transport took frames at ``now`` (monotonic seconds): it reads."""
        self.budget.clock(now)
        self.idle_since = self.budget.now

    @property
    def stalled(self) -> bool:
        """Whether it has held something for ``PRESSURE_STALL_S`` with nothing taken.

        Counted from its last take, or from the first sweep that saw it holding.
        """
        since = self.idle_since
        return since is not None and self.budget.now - since >= PRESSURE_STALL_S

    def excess(self, send_buffer: int) -> int:
        """Bytes of its topic messages to drop now for the budget (module text); 0 when none.

        Args:
            send_buffer: the connection's send buffer limit, bytes
                (``--send-buffer-limit``).

        Stalled while the budget is full: all it holds; else over the limit:
        what it holds past the larger of its share and ``READER_KEEP`` of
        ``send_buffer``.
        """
        budget = self.budget
        if not budget.pressed:
            return 0
        if self.stalled:
            return self.held
        if budget.used <= budget.limit:
            return 0
        return max(0, self.held - max(budget.share, int(send_buffer * READER_KEEP)))

    def close(self) -> None:
        """Give back everything (the connection ended); later charges are ignored."""
        if self.held:
            self.charge(-self.held)
        self.closed = True
