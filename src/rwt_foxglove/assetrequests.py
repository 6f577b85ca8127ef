"""One client's ``fetchAsset`` requests between the session and the driver, without I/O.

The session queues each request (``add``); the driver takes them one at a time
(``next``), reads the file off the event loop (``assets.AssetRoots.read``) and
hands the answer back to the session, which queues the response. The driver
reads the next file only once the client has taken the previous response
(``queued``), so a client holds at most one file's bytes in its queue
(``assets.MAX_ASSET_BYTES``) and ``MAX_PENDING_ASSETS`` requests: a client
that asks for more is answered at once with an error (docs/limits.md).
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from .protocol import FetchAsset

__all__ = ["ASSETS_CAPABILITY", "MAX_PENDING_ASSETS", "AssetRequests"]

ASSETS_CAPABILITY: Final = "assets"
MAX_PENDING_ASSETS: Final = 64
"""``fetchAsset`` requests of one client waiting to be read, at most (docs/limits.md)."""


class AssetRequests:
    """The waiting requests (first come, first read) and the responses still queued.

    Attributes:
        queued: responses with a file's outcome in the client's queue, not yet taken.
    """

    __slots__ = ("_waiting", "queued")

    def __init__(self) -> None:
        self._waiting: deque[FetchAsset] = deque()
        self.queued = 0

    def add(self, request: FetchAsset) -> bool:
        """Queue ``request``; False when ``MAX_PENDING_ASSETS`` already wait."""
        if len(self._waiting) >= MAX_PENDING_ASSETS:
            return False
        self._waiting.append(request)
        return True

    def next(self) -> FetchAsset | None:
        """The oldest waiting request, taken, or None."""
        return self._waiting.popleft() if self._waiting else None
