"""Fragmentation of large messages, both directions (spec 3.1.1, D19).

Outgoing: the text of one op is cut into chunks of ``fragment_size`` characters,
each sent as its own ``fragment`` op with the op's id (or a fresh one), integer
``num`` from 0 and integer ``total`` (the reference sends a float total and id 0,
REF §3.4). ``png`` ops are split the same way (D20), by their base64 ``data``.

Incoming: a ``Reassembler`` per connection (the reference shares one store among
all clients) collects parts by ``num`` in any order, refuses duplicates and
parts that disagree with earlier ones, bounds what it holds (D24) and forgets
messages that stop arriving. It reads no clock: ``now`` comes from the caller
and the session drives expiry from its timer.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Protocol

from ..codecs.json import encode_op
from ..errors import ConfigError, RemoteProtocolError
from ..ops import Fragment, Png

__all__ = [
    "FRAGMENT_OVERHEAD",
    "MAX_PARTS",
    "BudgetCharge",
    "FragmentBudget",
    "PartKind",
    "Reassembler",
    "SharedBudget",
    "fragment_frames",
    "fresh_id",
    "held_size",
    "split_text",
]

FRAGMENT_OVERHEAD = 64
"""Bytes charged per held part on top of its data, so tiny parts stay bounded."""


def held_size(text: str) -> int:
    """Count the bytes ``text`` takes in memory, as CPython stores strings.

    1, 2 or 4 per character, by its widest one. A held part costs this, not its
    length in characters, so astral characters cannot hold 4x the limit
    (docs/limits.md).
    """
    if text.isascii():
        return len(text)
    widest = ord(max(text))
    return len(text) * (1 if widest < 0x100 else 2 if widest < 0x10000 else 4)


MAX_PARTS = 10_000
"""The most parts one outgoing message is cut into (D24: a peer asking for
``fragment_size`` 1 must not make the server build millions of frames); a smaller
fragment size is raised for that message so that it fits."""

_fresh = itertools.count(1)


def fresh_id(op: str) -> str:
    """A new id for the parts of an op that has none: ``rwt:<op>:<n>``, unique per process.

    Never empty or 0: roslibjs ignores fragments whose id is falsy.
    """
    return f"rwt:{op}:{next(_fresh)}"


def split_text(text: str, size: int) -> list[str]:
    """Cut ``text`` into consecutive chunks of ``size`` characters (the last may be shorter).

    Args:
        text: the text to cut; empty text gives one empty chunk.
        size: characters per chunk, at least 1.

    Raises:
        ConfigError: ``size`` is below 1.
    """
    if size < 1:
        raise ConfigError(f"fragment size must be at least 1, got {size}")
    if not text:
        return [""]
    return [text[start : start + size] for start in range(0, len(text), size)]


def fragment_frames(text: str, op_id: str | int, size: int, *, op: str = "fragment") -> list[bytes]:
    """Build the ``fragment`` (or ``png``) ops that carry ``text`` in parts.

    Args:
        text: the JSON text of the op to send (for ``png``: its base64 data).
        op_id: the id every part carries (D19).
        size: characters of ``text`` per part.
        op: ``fragment``, or ``png`` for the parts of a PNG message (D20).

    Returns:
        One JSON frame per part, in order, ``{"op", "id", "data", "num", "total"}``;
        never more than ``MAX_PARTS``.
    """
    chunks = split_text(text, max(size, -(-len(text) // MAX_PARTS)))
    total = len(chunks)
    model = Png if op == "png" else Fragment
    return [
        encode_op(model(id=op_id, data=chunk, num=num, total=total))
        for num, chunk in enumerate(chunks)
    ]


class PartKind(StrEnum):
    """Which op the parts belong to: their ids live in separate spaces."""

    FRAGMENT = "fragment"
    PNG = "png"


class SharedBudget(Protocol):
    """A wider budget a ``FragmentBudget`` is counted in too (the server's memory budget, D44)."""

    def hold(self, cost: int) -> None:
        """Count ``cost`` bytes more (never refused: the sender's own bounds apply)."""

    def release(self, cost: int) -> None:
        """Count ``cost`` bytes fewer."""


class FragmentBudget:
    """The bytes of incomplete messages every connection of a server may hold together.

    Each connection's ``Reassembler`` is bounded by ``--max-message-size`` alone, so
    thousands of connections could hold thousands of times that; they all draw
    from this one budget (``--max-fragment-memory``, docs/limits.md), and a part
    that would take it past ``limit`` is refused. Frames still arriving on TCP and
    WebSocket connections draw from it too (``BudgetCharge``). What it holds is
    counted in ``parent`` as well, the server's memory budget (D44), which never
    refuses it: a sender's input is bounded by this budget and its own limits.

    Args:
        limit: bytes (``held_size`` plus ``FRAGMENT_OVERHEAD`` a part) held at once,
            over all connections.
        parent: the wider budget; None: this one alone.
    """

    __slots__ = ("limit", "parent", "used")

    def __init__(self, limit: int, parent: SharedBudget | None = None) -> None:
        self.limit = limit
        self.parent = parent
        self.used = 0

    def take(self, cost: int) -> bool:
        """Charge ``cost`` bytes if they fit under ``limit``; whether they were charged."""
        if self.used + cost > self.limit:
            return False
        self.used += cost
        if self.parent is not None:
            self.parent.hold(cost)
        return True

    def give(self, cost: int) -> None:
        """Return ``cost`` bytes charged before."""
        self.used -= cost
        if self.parent is not None:
            self.parent.release(cost)

    def refusal(self, what: str) -> str:
        """The status text for ``what`` (``message 'ID'``, ``frame``) refused by this budget."""
        return (
            f"{what} dropped: the server holds {self.limit} bytes of"
            " incomplete messages from all connections already (the server's limit)"
        )


class BudgetCharge:
    """What one reader's buffered partial frame holds of a ``FragmentBudget``.

    A frame still arriving (a TCP value without its end, a WebSocket frame or
    fragmented message) is kept until whole, up to ``--max-message-size`` per
    connection; as with incomplete ``fragment`` ops, every connection together
    may keep only the server-wide budget (docs/limits.md, per server).

    Args:
        budget: the server's budget; None charges nothing and refuses nothing.
    """

    __slots__ = ("budget", "held")

    def __init__(self, budget: FragmentBudget | None) -> None:
        self.budget = budget
        self.held = 0
        """Bytes charged now."""

    def hold(self, size: int) -> bool:
        """Charge ``size`` bytes in all (less than before gives the rest back).

        Returns:
            False when the growth does not fit in the budget; the charge is then
            unchanged and the caller drops what it buffered.
        """
        budget = self.budget
        if budget is None or size == self.held:
            return True
        if size < self.held:
            budget.give(self.held - size)
        elif not budget.take(size - self.held):
            return False
        self.held = size
        return True

    def release(self) -> None:
        """Give everything back (the frame completed or was dropped, the connection ended)."""
        self.hold(0)


@dataclass(slots=True)
class _Pending:
    total: int
    deadline: float
    size: int = 0
    parts: dict[int, str] = field(default_factory=dict)


class Reassembler:
    """The partly received messages of one connection.

    Args:
        max_bytes: the most bytes (``held_size``) held at once, over every pending message
            (each part costs its data plus ``FRAGMENT_OVERHEAD``); also the largest
            message that can be reassembled (``--max-message-size``).
        max_pending: the most messages pending at once (``--max-pending-fragments``).
        timeout_s: seconds after its latest part at which an incomplete message is
            forgotten (``--fragment-timeout``).
        shared: the server-wide budget every part is also charged to
            (``--max-fragment-memory``); None: this connection's bound alone.
    """

    def __init__(
        self,
        *,
        max_bytes: int,
        max_pending: int,
        timeout_s: float,
        shared: FragmentBudget | None = None,
    ) -> None:
        self.max_bytes = max_bytes
        self.max_pending = max_pending
        self.timeout_s = timeout_s
        self.shared = shared
        self._pending: dict[tuple[PartKind, str | int], _Pending] = {}
        self._bytes = 0

    def __len__(self) -> int:
        return len(self._pending)

    @property
    def held_bytes(self) -> int:
        """Characters (with per-part overhead) currently held."""
        return self._bytes

    def add(
        self, kind: PartKind, op_id: str | int, num: int, total: int, *, data: str, now: float
    ) -> str | None:
        """Take one part; return the whole text once every part arrived.

        Args:
            kind: the op that carried the part.
            op_id: the message id the parts share.
            num: index of this part, 0-based.
            total: number of parts.
            data: this part's text.
            now: monotonic seconds, for expiry.

        Returns:
            The parts' data joined in ``num`` order when complete, else None.

        Raises:
            RemoteProtocolError: ``num`` not below ``total``, a ``total`` that differs
                from earlier parts, a duplicate ``num``, too many pending messages,
                more than ``max_bytes`` held, or a part the server-wide ``shared``
                budget cannot take; a message whose part is refused for bytes is
                dropped whole, since it can never complete.
        """
        if num >= total:
            raise RemoteProtocolError(f"num {num} is not below total {total} (id {op_id!r})")
        key = (kind, op_id)
        entry = self._pending.get(key)
        if entry is None:
            if total == 1:
                self._check_size(key, held_size(data) + FRAGMENT_OVERHEAD)
                return data
            if len(self._pending) >= self.max_pending:
                raise RemoteProtocolError(
                    f"too many incomplete messages (limit {self.max_pending}); id {op_id!r} refused"
                )
            entry = self._pending[key] = _Pending(total, now + self.timeout_s)
        elif total != entry.total:
            raise RemoteProtocolError(
                f"total {total} differs from {entry.total} of earlier parts of id {op_id!r}"
            )
        elif num in entry.parts:
            raise RemoteProtocolError(f"duplicate part {num} of id {op_id!r}")
        cost = held_size(data) + FRAGMENT_OVERHEAD
        self._check_size(key, cost)
        if self.shared is not None and not self.shared.take(cost):
            self._drop(key)
            raise RemoteProtocolError(self.shared.refusal(f"message {op_id!r}"))
        entry.parts[num] = data
        entry.size += cost
        self._bytes += cost
        entry.deadline = now + self.timeout_s
        if len(entry.parts) < entry.total:
            return None
        self._drop(key)
        return "".join(entry.parts[i] for i in range(entry.total))

    def _check_size(self, key: tuple[PartKind, str | int], cost: int) -> None:
        if self._bytes + cost <= self.max_bytes:
            return
        self._drop(key)
        raise RemoteProtocolError(
            f"message {key[1]!r} dropped: incomplete messages would hold more than"
            f" {self.max_bytes} bytes"
        )

    def _drop(self, key: tuple[PartKind, str | int]) -> None:
        entry = self._pending.pop(key, None)
        if entry is not None:
            self._bytes -= entry.size
            if self.shared is not None:
                self.shared.give(entry.size)

    def next_deadline(self) -> float | None:
        """The earliest time at which a pending message expires, or None."""
        return min((e.deadline for e in self._pending.values()), default=None)

    def expire(self, now: float) -> list[tuple[PartKind, str | int, int, int]]:
        """Forget every message whose deadline is at or before ``now``.

        Returns:
            ``(kind, id, parts received, total)`` of each forgotten message.
        """
        expired = [key for key, entry in self._pending.items() if entry.deadline <= now]
        gone: list[tuple[PartKind, str | int, int, int]] = []
        for key in expired:
            entry = self._pending[key]
            gone.append((key[0], key[1], len(entry.parts), entry.total))
            self._drop(key)
        return gone

    def clear(self) -> None:
        """Forget everything (the connection closed)."""
        if self.shared is not None:
            self.shared.give(self._bytes)
        self._pending.clear()
        self._bytes = 0
