"""The Foxglove section of a client's bounds (docs/limits.md, Foxglove clients).

A Foxglove client is bound by the same per-client rules as a rosbridge client,
the shared ``ClientRules`` (``rwt_protocol.runtime.rules``: ``--send-buffer-limit``,
``--send-timeout``, ``--max-subscriptions``, ``--max-pending-calls``,
``--call-timeout``, ``--idle-timeout``, ``--hold-budget``); ``FoxgloveLimits``
holds only what the Foxglove protocol has and rosbridge does not.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

__all__ = [
    "ADVERTISE_BATCH_CHANNELS",
    "DEFAULT_MAX_MESSAGES",
    "MAX_PLAYBACK_REQUEST_ID_BYTES",
    "FoxgloveLimits",
]

MAX_PLAYBACK_REQUEST_ID_BYTES: Final = 256
"""The longest request id of a playback control request (UTF-8 bytes). The Foxglove
app sends a short generated id; a longer one is refused, so an answer, which carries
it back to every client with ``playbackControl``, stays small."""

DEFAULT_MAX_MESSAGES: Final = 1024
"""Messages a client's queue holds before dropping (the SDK's default backlog)."""

ADVERTISE_BATCH_CHANNELS: Final = 256
"""Channels (or services) one ``advertise`` (``advertiseServices``) frame carries at
most: a client new to a graph of thousands of topics gets them in frames of this
many, the next once it took the last, not megabytes at once (docs/limits.md)."""


@dataclass(frozen=True, slots=True)
class FoxgloveLimits:
    """The Foxglove section of a client's bounds (docs/limits.md, Foxglove clients).

    Attributes:
        max_channels: server channels (topics) a client is advertised at once;
            further topics are not advertised until some go.
        max_client_channels: channels a client may advertise at once.
        max_queue_messages: topic messages (and time frames) queued for the client
            before the oldest is dropped, besides ``--send-buffer-limit``'s bytes.
        max_parameter_subscriptions: parameters a client may watch at once.
        advertise_batch: channels or services per ``advertise`` frame
            (``ADVERTISE_BATCH_CHANNELS``).
    """

    max_channels: int = 10_000
    max_client_channels: int = 1024
    max_queue_messages: int = DEFAULT_MAX_MESSAGES
    max_parameter_subscriptions: int = 4096
    advertise_batch: int = ADVERTISE_BATCH_CHANNELS
