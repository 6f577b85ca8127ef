"""Outgoing frames joined into few writes, a large payload never copied.

Each connection's writer (and the direct send) turns a batch of frames into the
writes of its transport: many small frames are joined, so a burst costs few
system calls; a large payload, which every subscriber of the same form shares
(``OutFrame``: encoded once), is written as it is, so no connection copies it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["WRITE_BATCH", "coalesce"]

WRITE_BATCH = 65536
"""Bytes of small frames joined into one write; a payload this large or larger goes alone."""


def coalesce(frames: Iterable[tuple[bytes, bytes, bytes]]) -> list[bytes]:
    """The writes that send ``frames`` in order.

    Args:
        frames: each frame as ``(prefix, payload, suffix)``: the transport's
            framing around the payload (a WebSocket header; a TCP line's
            newline), empty where there is none.

    Returns:
        the bytes to write, in order: small frames joined into writes of about
        ``WRITE_BATCH`` bytes, each large payload as its own write (the same
        ``bytes`` object, not a copy).
    """
    writes: list[bytes] = []
    batch: list[bytes] = []
    size = 0
    for prefix, payload, suffix in frames:
        if len(payload) >= WRITE_BATCH:
            if prefix:
                batch.append(prefix)
            if batch:
                writes.append(b"".join(batch))
            writes.append(payload)
            batch, size = ([suffix], len(suffix)) if suffix else ([], 0)
            continue
        batch += (prefix, payload, suffix)
        size += len(prefix) + len(payload) + len(suffix)
        if size >= WRITE_BATCH:
            writes.append(b"".join(batch))
            batch, size = [], 0
    if batch:
        writes.append(b"".join(batch))
    return writes
