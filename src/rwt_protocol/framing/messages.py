"""Whole WebSocket messages from their frames (RFC 6455 5.4), for both roles.

A message may arrive as a first frame (text or binary) and continuation frames;
the server's channel and the client's connection both join them here, within
the incoming size limit (``--max-message-size``, D24). Sans-IO: the caller
passes each frame's opcode (``FrameKind.of``) and closes with 1009 when ``add``
refuses.
"""

from __future__ import annotations

from enum import IntEnum

from ..errors import RemoteProtocolError
from ..runtime.inframes import InFrame

__all__ = ["FrameKind", "MessageAssembler", "MessageTooBigError"]


class FrameKind(IntEnum):
    """The data frames of RFC 6455 5.6, by opcode; control frames are not part of a message."""

    CONTINUATION = 0x0
    TEXT = 0x1
    BINARY = 0x2

    @classmethod
    def of(cls, opcode: int) -> FrameKind | None:
        """The kind of a frame with ``opcode``; None for control frames (ping, pong, close)."""
        return cls(opcode) if opcode <= cls.BINARY else None


class MessageTooBigError(RemoteProtocolError):
    """A message grew past the limit; close the connection with 1009."""


class MessageAssembler:
    """Join the data frames of one message at a time.

    Args:
        max_bytes: the largest message, bytes; a larger one is refused as soon
            as its frames pass the limit, without holding the rest.
    """

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self._parts: list[bytes] = []
        self._size = 0
        self._binary = False

    @property
    def held(self) -> int:
        """Bytes of the message begun and not yet whole."""
        return self._size

    def clear(self) -> None:
        """Forget the message begun (the connection is closing)."""
        self._parts, self._size = [], 0

    def add(
        self, kind: FrameKind, data: bytes | bytearray | memoryview, *, fin: bool
    ) -> InFrame | None:
        """Take one data frame; return the whole message once its last frame arrived.

        Args:
            kind: the frame's kind; a text or binary frame starts a new message.
            data: the frame's payload.
            fin: whether this is the message's last frame.

        Returns:
            The message (``binary`` for a binary one), or None while incomplete.

        Raises:
            MessageTooBigError: the message passed ``max_bytes`` (it is dropped).
        """
        if kind is not FrameKind.CONTINUATION:
            self._parts, self._size = [], 0
            self._binary = kind is FrameKind.BINARY
        self._parts.append(bytes(data))
        self._size += len(data)
        if self._size > self.max_bytes:
            self._parts, self._size = [], 0
            raise MessageTooBigError(f"message too big (over {self.max_bytes} bytes)")
        if not fin:
            return None
        message = b"".join(self._parts)
        self._parts, self._size = [], 0
        return InFrame(message, binary=self._binary)
