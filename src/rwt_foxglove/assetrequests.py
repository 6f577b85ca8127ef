"""One client's ``fetchAsset`` requests, read one at a time off the event loop, without I/O.

The session queues each request (``AssetRequests.add``) and turns the oldest into
an ``AssetJob``, a background job its transport runs in a worker thread
(``SessionBase.add_job``); the job's outcome comes back to the session, which
queues the response. The next file is read only once the client has taken the
previous response from the queue (``queued``), so a client holds at most one
file's bytes (``assets.MAX_ASSET_BYTES``) and ``MAX_PENDING_ASSETS`` requests: a
client that asks for more is answered at once with an error (docs/limits.md).
A connection that closes drops its queue, and the bytes with it.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, Protocol

if TYPE_CHECKING:
    from .protocol import FetchAsset

__all__ = ["ASSETS_CAPABILITY", "MAX_PENDING_ASSETS", "AssetJob", "AssetReader", "AssetRequests"]

ASSETS_CAPABILITY: Final = "assets"
MAX_PENDING_ASSETS: Final = 64
"""``fetchAsset`` requests of one client waiting to be read, at most (docs/limits.md)."""


class AssetReader(Protocol):
    """Reads the file a ``package://`` URI names (``assets.AssetRoots``): disk I/O."""

    def read(self, uri: str) -> bytes:
        """The file's bytes.

        Raises:
            RwtError: the URI is refused or the file cannot be read (its text goes
                to the client: ``assets.AssetError``).
        """


@dataclass(frozen=True, slots=True)
class AssetJob:
    """Reading one requested file: a background job (``contract.Job``)."""

    reader: AssetReader
    request: FetchAsset
    ready_at: float = 0.0

    def run(self) -> bytes:
        """Read the file (in a worker thread)."""
        return self.reader.read(self.request.uri)


class AssetRequests:
    """The waiting requests (first come, first read) and the file in hand.

    Attributes:
        queued: responses with a file's outcome in the client's queue, not yet taken.
        reading: a job of this client is reading a file now.
    """

    __slots__ = ("_waiting", "queued", "reading")

    def __init__(self) -> None:
        self._waiting: deque[FetchAsset] = deque()
        self.queued = 0
        self.reading = False

    def add(self, request: FetchAsset) -> bool:
        """Queue ``request``; False when ``MAX_PENDING_ASSETS`` already wait."""
        if len(self._waiting) >= MAX_PENDING_ASSETS:
            return False
        self._waiting.append(request)
        return True

    def next(self) -> FetchAsset | None:
        """The oldest waiting request to read now, taken, or None (one file at a time)."""
        if self.reading or self.queued or not self._waiting:
            return None
        return self._waiting.popleft()

    def clear(self) -> None:
        """Forget every request (the connection ended)."""
        self._waiting.clear()
