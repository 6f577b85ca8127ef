"""One server-wide memory budget for what clients make the server hold (D44, docs/limits.md).

Each connection is bounded on its own (``--send-buffer-limit``, ``--max-message-size``,
the png backlog, one asset file), but with thousands of connections the sum of
those bounds is gigabytes: 30 Foxglove clients that each fetched a 10 MB asset
and never read held 357 MB, and nothing bounded the total. ``MemoryBudget`` is the
bound on the total (``--memory-budget``). Charged to it: every connection's
outbox (topic messages, replies, asset files) and what its transport took from it
and is still writing, its png messages waiting to be deflated, a WebRTC peer's
input not read yet (each connection's ``MemoryAccount``), and the incomplete
messages and frames of every connection (``FragmentBudget`` draws from it).

The per-client bounds stay as they are, inside the budget. While it is full
(charged past its ``limit``, or something was refused for want of room), the
rule takes from the clients that do not read, the slow-consumer rule (D24):

- a connection that took nothing from its outbox between two sweeps (at least
  ``PRESSURE_SWEEP_S`` apart) while holding something is *stalled*: it keeps
  only its newest topic message, the oldest dropped first;
- over the limit, any other connection keeps at most the larger of its share
  (``limit`` over the connections holding anything) and half its send buffer,
  the high watermark at which input backpressure holds a publisher for a
  reader: a reader keeping up loses nothing;
- a connection holding more than ``PRESSURE_FLOOR_BYTES`` that takes nothing for
  ``--send-timeout`` is closed as a slow consumer, whatever it holds (replies,
  an asset file): replies are never dropped, so this is how they are freed;
- what would grow the total and can be refused is refused, with a text naming
  ``--memory-budget`` (``refusal``): a Foxglove asset file, an incomplete
  message's part, a frame still arriving.

A reader's replies and its input are never refused or dropped for the budget.
The sweep is one pass over the connections holding anything, at most once per
``PRESSURE_SWEEP_S`` and only while the budget is full; time comes from the
caller (sans-IO).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = [
    "DEFAULT_MEMORY_BUDGET",
    "MEMORY_BUDGET_OPTION",
    "PRESSURE_FLOOR_BYTES",
    "PRESSURE_SWEEP_S",
    "MemoryAccount",
    "MemoryBudget",
]

DEFAULT_MEMORY_BUDGET: Final = 1024 * 1024 * 1024
"""Default ``--memory-budget``, bytes: 1 GiB, 64 connections' whole send buffers (16 MiB)."""

MEMORY_BUDGET_OPTION: Final = "--memory-budget"
"""The option that sets the budget, named to a client that meets it."""

PRESSURE_SWEEP_S: Final = 1.0
"""Seconds between two passes over the connections while the budget is full: a
connection that took nothing between two passes is stalled (module text)."""

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
    """

    __slots__ = ("_holders", "_next_sweep", "limit", "used", "wanted")

    def __init__(self, limit: int = DEFAULT_MEMORY_BUDGET) -> None:
        self.limit = limit
        self.used = 0
        self.wanted = False
        self._holders: set[MemoryAccount] = set()  # the accounts holding anything
        self._next_sweep = float("-inf")

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

    def take(self, cost: int) -> bool:
        """Charge ``cost`` bytes held by no connection's account if they fit; whether they did.

        What the incomplete messages hold (``FragmentBudget``'s parent) is charged so.
        """
        if not self.fits(cost):
            return False
        self.used += cost
        return True

    def give(self, cost: int) -> None:
        """Return ``cost`` bytes charged by ``take``."""
        self.used -= cost

    def refusal(self, what: str) -> str:
        """The text a client gets for ``what`` (``message 'ID'``, a URI) refused for room."""
        return (
            f"{what} refused: the server's memory budget is full ({self.used} of {self.limit} "
            f"bytes held for its clients, {MEMORY_BUDGET_OPTION}): try again later"
        )

    def sweep(self, now: float) -> None:
        """While the budget is full, judge and tell each connection holding anything.

        At most once per ``PRESSURE_SWEEP_S``; ``now`` is monotonic seconds. A
        connection that took nothing since the last sweep, holding something at
        both, is stalled; each gets ``on_pressure(now)`` (module text).
        """
        if now < self._next_sweep or not self.pressed:
            return
        self._next_sweep = now + PRESSURE_SWEEP_S
        self.wanted = False
        for account in list(self._holders):
            account.stalled = account.swept and account.takes == account.takes_swept
            account.swept = True
            account.takes_swept = account.takes
            if account.on_pressure is not None:
                account.on_pressure(now)


class MemoryAccount:
    """What one connection holds of a ``MemoryBudget``, and whether it reads.

    Args:
        budget: the server's budget.
        on_pressure: called with ``now`` by the budget's sweep while it is full.

    Attributes:
        held: bytes this connection holds now.
        takes: how many times its transport took from its outbox (``took``).
        stalled: it took nothing between the last two sweeps (module text).
        swept: it held something at the last sweep (and since).
        takes_swept: ``takes`` at the last sweep.
    """

    __slots__ = (
        "budget",
        "closed",
        "held",
        "on_pressure",
        "stalled",
        "swept",
        "takes",
        "takes_swept",
    )

    def __init__(
        self, budget: MemoryBudget, on_pressure: Callable[[float], None] | None = None
    ) -> None:
        self.budget = budget
        self.held = 0
        self.on_pressure = on_pressure
        self.closed = False
        self.takes = 0
        self.takes_swept = 0
        self.stalled = False
        self.swept = False

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
        elif not self.held:
            budget._holders.discard(self)
            self.stalled = self.swept = False  # it holds nothing: it read, or lost, all

    def took(self) -> None:
        """Its transport took frames: it reads."""
        self.takes += 1
        self.stalled = False

    def excess(self, keep: int) -> int:
        """Bytes of its topic messages to drop now for the budget (module text); 0 when none.

        Args:
            keep: what a connection that reads may keep over its share, bytes
                (its outbox's high watermark).
        """
        budget = self.budget
        if self.stalled:
            return self.held if budget.pressed else 0
        if budget.used <= budget.limit:
            return 0
        return max(0, self.held - max(budget.share, keep))

    def close(self) -> None:
        """Give back everything (the connection ended); later charges are ignored."""
        if self.held:
            self.charge(-self.held)
        self.closed = True
