"""The error of record and replay."""

from __future__ import annotations

from rwt_protocol.errors import RwtError

__all__ = ["BagError"]


class BagError(RwtError):
    """A bag cannot be written or read: its text names the file, topic and type."""
