"""The bounds of one Foxglove client (docs/limits.md, Foxglove clients)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from .outqueue import DEFAULT_MAX_BYTES, DEFAULT_MAX_MESSAGES

__all__ = ["MAX_PLAYBACK_REQUEST_ID_BYTES", "FoxgloveLimits"]

MAX_PLAYBACK_REQUEST_ID_BYTES: Final = 256
"""The longest request id of a playback control request (UTF-8 bytes). The Foxglove
app sends a short generated id; a longer one is refused, so an answer, which carries
it back to every client with ``playbackControl``, stays small."""


@dataclass(frozen=True, slots=True)
class FoxgloveLimits:
    """Bounds of one Foxglove client (docs/limits.md, Foxglove).

    Attributes:
        max_channels: server channels (topics) a client is advertised at once;
            further topics are not advertised until some go.
        max_subscriptions: subscriptions a client may hold at once.
        max_client_channels: channels a client may advertise at once.
        max_queue_bytes: bytes of message data queued for the client before
            the oldest is dropped.
        max_queue_messages: messages queued before the oldest is dropped.
        batch_bytes: about how many bytes the driver sends per write.
        max_pending_calls: service calls a client may have in flight at once
            (the Foxglove SDK's server allows 32); one more fails at once.
        call_timeout_s: seconds a service call may wait for its response
            before it fails (checked at each sync, so up to one sync later).
        max_parameter_subscriptions: parameters a client may watch at once.
    """

    max_channels: int = 10_000
    max_subscriptions: int = 4096
    max_client_channels: int = 1024
    max_queue_bytes: int = DEFAULT_MAX_BYTES
    max_queue_messages: int = DEFAULT_MAX_MESSAGES
    batch_bytes: int = 1024 * 1024
    max_pending_calls: int = 32
    call_timeout_s: float = 60.0
    max_parameter_subscriptions: int = 4096
