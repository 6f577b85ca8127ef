"""The bounded queue of frames waiting to go out on one connection.

PROTOCOL-DECISIONS D24: the bytes queued for a peer are bounded; above the bound
the oldest *topic* messages are dropped, never service responses, action results
or status messages. Drops are counted so the session can report them. The parts
of one fragmented message share a ``group`` and are dropped together, so that a
peer is not left with a message it can never complete (D19); a message whose
first parts were already taken is never cut either. The writer takes frames in
bounded batches (``take``), so the frames a transport holds outside the queue
stay small too. Dropping is amortised O(1) per frame.
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
        self._kept_bytes = 0
        self._sending_group: object = None  # partly taken: the rest must go too
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
        self.extend((frame,))

    def extend(self, frames: Iterable[OutFrame]) -> None:
        """Queue several frames (the parts of one message), then drop if over the bound.

        Queueing every part before dropping lets a message's parts go together.
        """
        for frame in frames:
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
        frames: list[OutFrame] = []
        taken = 0
        while self._frames and (
            max_bytes is None or not frames or taken + len(self._frames[0].data) <= max_bytes
        ):
            frame = self._frames.popleft()
            frames.append(frame)
            taken += len(frame.data)
            if not frame.droppable:
                self._kept_bytes -= len(frame.data)
        self._bytes -= taken
        last = frames[-1].group if frames else None
        following = self._frames[0].group if self._frames else None
        self._sending_group = last if last is not None and last == following else None
        return frames

    def drain(self) -> list[OutFrame]:
        """Remove and return every queued frame, oldest first."""
        return self.take()

    def _shed(self) -> None:
        kept: list[OutFrame] = []
        groups: set[object] = set()
        while self._frames and self._bytes > self.limit_bytes:
            frame = self._frames.popleft()
            if frame.droppable and (frame.group is None or frame.group != self._sending_group):
                self._drop(frame, groups)
            else:
                kept.append(frame)
        # The rest of a message whose first parts were dropped follows right after them.
        while (
            self._frames and self._frames[0].group is not None and self._frames[0].group in groups
        ):
            self._drop(self._frames.popleft(), groups)
        self._frames.extendleft(reversed(kept))  # the kept ones keep their place

    def _drop(self, frame: OutFrame, groups: set[object]) -> None:
        self._bytes -= len(frame.data)
        if frame.group is None:
            self.dropped += 1
        elif frame.group not in groups:
            groups.add(frame.group)
            self.dropped += 1
