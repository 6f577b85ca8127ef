"""The bounded queue of frames waiting to go out on one connection.

PROTOCOL-DECISIONS D24: the bytes queued for a peer are bounded; above the bound
the oldest *topic* messages are dropped, never service responses, action results
or status messages. Drops are counted so the session can report them. The
writer takes frames in bounded batches (``take``), so the frames a transport
holds outside the queue stay small too.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

__all__ = ["OutFrame", "Outbox"]


@dataclass(frozen=True, slots=True)
class OutFrame:
    """One frame to send.

    Attributes:
        data: the payload (UTF-8 JSON text or CBOR bytes).
        binary: send as a binary frame (CBOR, D27) rather than text.
        droppable: may be dropped under pressure (topic messages only).
    """

    data: bytes
    binary: bool = False
    droppable: bool = False


class Outbox:
    """FIFO of ``OutFrame`` with a byte bound that drops the oldest droppable frames.

    Args:
        limit_bytes: the most payload bytes kept queued; frames that may not be
            dropped are always queued, even beyond it.
    """

    def __init__(self, limit_bytes: int) -> None:
        self._frames: deque[OutFrame] = deque()
        self._bytes = 0
        self._kept_bytes = 0
        self.limit_bytes = limit_bytes
        self.dropped = 0

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def queued_bytes(self) -> int:
        """Payload bytes currently queued."""
        return self._bytes

    @property
    def undroppable_bytes(self) -> int:
        """Payload bytes of queued frames that may not be dropped."""
        return self._kept_bytes

    @property
    def over_limit(self) -> bool:
        """Whether more than ``limit_bytes`` are queued (only undroppable frames remain over it)."""
        return self._bytes > self.limit_bytes

    def push(self, frame: OutFrame) -> None:
        """Queue ``frame``, dropping the oldest droppable frames if over the bound."""
        self._frames.append(frame)
        self._bytes += len(frame.data)
        if not frame.droppable:
            self._kept_bytes += len(frame.data)
        if self._bytes > self.limit_bytes:
            self._shed()

    def take(self, max_bytes: int | None = None) -> list[OutFrame]:
        """Remove and return the oldest frames, oldest first.

        Args:
            max_bytes: stop once this many payload bytes are taken (at least one
                frame is taken when any is queued); None takes everything.
        """
        if max_bytes is None:
            frames = list(self._frames)
            self._frames.clear()
            self._bytes = self._kept_bytes = 0
            return frames
        frames = []
        taken = 0
        while self._frames and (not frames or taken + len(self._frames[0].data) <= max_bytes):
            frame = self._frames.popleft()
            frames.append(frame)
            taken += len(frame.data)
            if not frame.droppable:
                self._kept_bytes -= len(frame.data)
        self._bytes -= taken
        return frames

    def _shed(self) -> None:
        kept: list[OutFrame] = []
        while self._frames and self._bytes > self.limit_bytes:
            frame = self._frames.popleft()
            if frame.droppable:
                self._bytes -= len(frame.data)
                self.dropped += 1
            else:
                kept.append(frame)
        self._frames.extendleft(reversed(kept))  # the undroppable ones keep their place
