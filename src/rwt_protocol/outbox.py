"""The bounded queue of frames waiting to go out on one connection.

PROTOCOL-DECISIONS D24: the bytes queued for a peer are bounded; above the bound
the oldest *topic* messages are dropped, never service responses, action results
or status messages. Drops are counted so the session can report them. The parts
of one fragmented message share a ``group`` and are dropped together, so that a
peer is not left with a message it can never complete (D19).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["OutFrame", "Outbox"]


@dataclass(frozen=True, slots=True)
class OutFrame:
    """One frame to send.

    Attributes:
        data: the payload (UTF-8 JSON text or CBOR bytes).
        binary: send as a binary frame (CBOR, D27) rather than text.
        droppable: may be dropped under pressure (topic messages only).
        group: the parts of one fragmented message share a group (any hashable
            that no other message uses); None for a whole message.
    """

    data: bytes
    binary: bool = False
    droppable: bool = False
    group: object = None


class Outbox:
    """FIFO of ``OutFrame`` with a byte bound that drops the oldest droppable frames.

    Args:
        limit_bytes: the most payload bytes kept queued; frames that may not be
            dropped are always queued, even beyond it.
    """

    def __init__(self, limit_bytes: int) -> None:
        self._frames: deque[OutFrame] = deque()
        self._bytes = 0
        self.limit_bytes = limit_bytes
        self.dropped = 0

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def queued_bytes(self) -> int:
        """Payload bytes currently queued."""
        return self._bytes

    def push(self, frame: OutFrame) -> None:
        """Queue ``frame``, dropping the oldest droppable frames if over the bound."""
        self._frames.append(frame)
        self._bytes += len(frame.data)
        if self._bytes > self.limit_bytes:
            self._shed()

    def extend(self, frames: Iterable[OutFrame]) -> None:
        """Queue several frames (the parts of one message), then drop if over the bound.

        Queueing every part before dropping lets a message's parts go together.
        """
        for frame in frames:
            self._frames.append(frame)
            self._bytes += len(frame.data)
        if self._bytes > self.limit_bytes:
            self._shed()

    def drain(self) -> list[OutFrame]:
        """Remove and return every queued frame, oldest first."""
        frames = list(self._frames)
        self._frames.clear()
        self._bytes = 0
        return frames

    def _shed(self) -> None:
        kept: deque[OutFrame] = deque()
        groups: set[object] = set()
        while self._frames and self._bytes > self.limit_bytes:
            frame = self._frames.popleft()
            if frame.droppable:
                self._drop(frame, groups)
            else:
                kept.append(frame)
        for frame in self._frames:
            if frame.group is not None and frame.group in groups:
                self._drop(frame, groups)
            else:
                kept.append(frame)
        self._frames = kept

    def _drop(self, frame: OutFrame, groups: set[object]) -> None:
        self._bytes -= len(frame.data)
        if frame.group is None:
            self.dropped += 1
        elif frame.group not in groups:
            groups.add(frame.group)
            self.dropped += 1
