"""What a Zenoh peer may make an rwt process hold: the link's limits (docs/limits.md).

A peer on the Zenoh network is trusted with the graph's names and messages, not
with this process's memory or event loop. Each limit here has an option of
``rwt serve`` and a section in docs/limits.md, "Zenoh peers: what they are trusted
with".
"""

from __future__ import annotations

__all__ = [
    "MAX_OUTBOX_BYTES",
    "MAX_QUEUED_BYTES",
    "MAX_QUEUED_SAMPLES",
    "MAX_REMOTE_ENTITIES",
    "RELIABLE_WAIT_S",
    "SAMPLE_OVERHEAD",
]

MAX_QUEUED_BYTES = 64 * 1024 * 1024
"""Bytes of remote samples waiting for the event loop (``--zenoh-queue-bytes``).

Past it the oldest samples of the topic holding the most are dropped, as a
keep-last depth would; a sample larger than this is dropped on arrival, and Zenoh
itself refuses messages larger than it (``transport/link/rx/max_message_size``)."""

MAX_OUTBOX_BYTES = 256 * 1024 * 1024
"""Bytes of local samples waiting for Zenoh's blocking ``put`` on the outbox thread
(``--zenoh-outbox-bytes``). Past half of it the publishing connection's reader
waits until a quarter, within its hold budget (``rwt_graph.link.Backlog``); past
all of it (an in-process publisher, which is never held; a Zenoh peer stalled
past the budget) the oldest samples of the topic holding the most are dropped,
logged once per episode."""

RELIABLE_WAIT_S = 10.0
"""Seconds a Zenoh thread waits for room in a full inbox with a reliable sample
(one put with congestion control BLOCK) before dropping as above. The wait holds
the sending peer back over TCP, so a burst is delivered whole; the bound keeps a
stalled event loop from stalling Zenoh's threads for ever (docs/zenoh.md,
"Reliability")."""

MAX_QUEUED_SAMPLES = 100_000
"""Remote samples waiting for the event loop, however small (dropped as above)."""

SAMPLE_OVERHEAD = 256
"""Bytes a waiting sample costs besides its payload and attachment (its records)."""

MAX_REMOTE_ENTITIES = 50_000
"""Remote Zenoh entities (liveliness tokens: nodes, publishers, subscriptions,
services) mirrored in the graph at once (``--zenoh-max-entities``); tokens past it
are ignored, counted in the log, until others go."""
