"""What a worker of ``rwt serve --workers N`` held, readable by its parent after it died.

Each worker keeps the number of connections it serves in a file of 8 bytes its
parent made (``--worker-state FILE``, set by the parent), written through a shared
memory map on every connection opened or closed: a store, no system call. When the
worker dies, however it dies (SIGKILL included), the file still holds the count its
last connection change wrote, and the parent logs it with ``event=worker_exit``
(docs/scaling.md): the clients that lost their connection and must reconnect.
"""

from __future__ import annotations

import mmap
import os
import struct

__all__ = ["STATE_PREFIX", "ConnectionCountWriter", "read_count", "reset_count"]

STATE_PREFIX = "worker-"
"""A worker's count file is ``<state folder>/worker-<index>`` (``workers.WorkerPlan.state``)."""
_COUNT = struct.Struct("<q")


def reset_count(path: str) -> None:
    """Make or zero the count file ``path`` before a worker starts.

    Raises:
        OSError: it cannot be written.
    """
    with open(path, "wb") as file:
        file.write(_COUNT.pack(0))


def read_count(path: str) -> int | None:
    """The count the worker of ``path`` last wrote; None if the file is missing or short."""
    try:
        with open(path, "rb") as file:
            data = file.read(_COUNT.size)
    except OSError:
        return None
    return _COUNT.unpack(data)[0] if len(data) == _COUNT.size else None


class ConnectionCountWriter:
    """The worker's side: ``write(n)`` stores its connection count in the shared file.

    Args:
        path: the file the parent made (``reset_count``).

    Raises:
        OSError: the file cannot be opened or mapped.
    """

    def __init__(self, path: str) -> None:
        fd = os.open(path, os.O_RDWR)
        try:
            if os.fstat(fd).st_size < _COUNT.size:
                os.ftruncate(fd, _COUNT.size)
            self._map = mmap.mmap(fd, _COUNT.size)
        finally:
            os.close(fd)

    def write(self, count: int) -> None:
        """Store ``count`` (connections served now)."""
        _COUNT.pack_into(self._map, 0, count)

    def close(self) -> None:
        """Unmap the file (the count written stays in it)."""
        self._map.close()
