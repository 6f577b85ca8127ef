"""A Foxglove client's outgoing queue: bounded in bytes and messages, oldest data dropped.

Why its own queue: the rosbridge outbox (``rwt_protocol.server.outbox``) bounds
bytes only and knows fragment groups; a Foxglove client gets whole binary
messages, and foxglove_bridge bounds its backlog in messages too. Control
frames (``advertise``, ``status``...) are never dropped; message data is, oldest
first, and each episode of drops (from the first drop until the queue is empty
again) is told to the client in one warning ``status`` (docs/foxglove.md).
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from rwt_protocol.server.outbox import OutFrame

__all__ = ["DEFAULT_MAX_BYTES", "DEFAULT_MAX_MESSAGES", "OutQueue"]

DEFAULT_MAX_BYTES: Final = 32 * 1024 * 1024
"""Bytes of message data a client's queue holds before dropping (docs/limits.md)."""
DEFAULT_MAX_MESSAGES: Final = 1024
"""Messages a client's queue holds before dropping (the SDK's default backlog, docs/limits.md)."""


class OutQueue:
    """FIFO of ``OutFrame``s; message data (``droppable``) past a bound drops the oldest data.

    Args:
        max_bytes: bytes of message data kept; the newest message is kept even
            when it alone is larger.
        max_messages: messages of data kept.

    Attributes:
        data_bytes: bytes of message data queued (read only: an attribute, not a
            property, as it is read per message).
        dropped: data frames dropped so far.
    """

    def __init__(
        self, max_bytes: int = DEFAULT_MAX_BYTES, max_messages: int = DEFAULT_MAX_MESSAGES
    ) -> None:
        self.max_bytes = max_bytes
        self.max_messages = max(1, max_messages)
        self._frames: deque[OutFrame] = deque()
        self._control_bytes = 0  # of the frames that are not data (``take``)
        self.data_bytes = 0
        self._data_count = 0
        self.dropped = 0
        self._peak = 0  # ``peak_bytes`` before the bytes queued now
        self._episode_drops = 0  # drops since the queue was last empty
        self._told = False  # the client heard of this episode

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def peak_bytes(self) -> int:
        """The most bytes of message data held at once (after drops)."""
        # kept when data leaves (``take``, drops), not per push: between two of those the
        # queue only grows, so its peak is where it stood before one of them, or now
        return max(self._peak, self.data_bytes)

    @property
    def data_count(self) -> int:
        """Messages of data queued."""
        return self._data_count

    def push(self, frame: OutFrame) -> bool:
        """Queue ``frame``; drop the oldest data while over a bound.

        Returns:
            Whether this push began an episode of drops that the client has not
            been told of (the caller queues the warning then).
        """
        self._frames.append(frame)
        if not frame.droppable:
            self._control_bytes += len(frame.data)
            return False
        # per message and client: the fewest steps while within the bounds
        self._data_count += 1
        data_bytes = self.data_bytes = self.data_bytes + len(frame.data)
        if self._data_count <= self.max_messages and data_bytes <= self.max_bytes:
            return False
        self._peak = max(self._peak, data_bytes - len(frame.data))  # what it held before
        self._drop_oldest()
        self._peak = max(self._peak, self.data_bytes)
        if not self._episode_drops or self._told:  # (one message alone over the bytes: kept)
            return False
        self._told = True
        return True

    def _drop_oldest(self) -> None:
        kept: deque[OutFrame] = deque()
        frames = self._frames
        # the newest frame (the one just pushed) always stays
        while (
            frames
            and self._data_count > 1
            and (self._data_count > self.max_messages or self.data_bytes > self.max_bytes)
        ):
            frame = frames.popleft()
            if frame.droppable:
                self.data_bytes -= len(frame.data)
                self._data_count -= 1
                self.dropped += 1
                self._episode_drops += 1
            else:
                kept.append(frame)
        kept.extend(frames)
        self._frames = kept

    @property
    def episode_drops(self) -> int:
        """Data frames dropped since the queue was last empty."""
        return self._episode_drops

    def take(self, max_bytes: int) -> list[OutFrame]:
        """Take frames, oldest first, about ``max_bytes`` of them (at least one).

        An empty queue ends the episode of drops.
        """
        frames = self._frames
        self._peak = max(self._peak, self.data_bytes)
        if self._control_bytes + self.data_bytes < max_bytes:  # all of them: as the loop would
            taken = list(frames)
            frames.clear()
            self._control_bytes = self.data_bytes = self._data_count = 0
            self._episode_drops = 0
            self._told = False
            return taken
        taken = []
        size = 0
        data_bytes = data_count = 0  # of the data frames taken
        while frames and (not taken or size < max_bytes):
            frame = frames.popleft()
            taken.append(frame)
            length = len(frame.data)
            size += length
            if frame.droppable:
                data_bytes += length
                data_count += 1
        self._control_bytes -= size - data_bytes
        self.data_bytes -= data_bytes
        self._data_count -= data_count
        if not frames:
            self._episode_drops = 0
            self._told = False
        return taken
