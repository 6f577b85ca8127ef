"""What a transport hands a session: whole frames, and what could not become one.

Every transport's framer (``rwt_protocol.framing``, a WebSocket's messages, a
data channel's) yields these, whatever protocol the session speaks; the
connection runtime (``rwt_transports.pump``) hands each ``InFrame`` to the
session and reports each ``FramingError`` in the session's own words.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

__all__ = ["FramerEvent", "FramingError", "InFrame", "LossyInFrame"]


@dataclass(frozen=True, slots=True)
class InFrame:
    """One whole incoming frame.

    Attributes:
        data: the frame's bytes (a JSON text, or one CBOR item when ``binary``).
        binary: the frame is CBOR (D21), not JSON text.
        lossy: it came on the transport's lossy channel (``LossyInFrame``, D36).
    """

    data: bytes
    binary: bool = False
    lossy: ClassVar[bool] = False


@dataclass(frozen=True, slots=True)
class LossyInFrame(InFrame):
    """One whole frame that came on a transport's lossy channel (WebRTC's, D36)."""

    lossy: ClassVar[bool] = True


@dataclass(frozen=True, slots=True)
class FramingError:
    """Something in the stream could not become a frame (it was skipped).

    Attributes:
        message: lowercase text for a ``status`` frame (D1).
        fatal: the stream cannot be followed any more; the connection must close.
    """

    message: str
    fatal: bool = False


FramerEvent = InFrame | FramingError
"""What a framer yields: frames, and reports of what it skipped."""
