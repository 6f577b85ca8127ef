"""Which client each parameter of the store is charged to, and how much each holds.

A parameter a client set (a rosbridge or Foxglove connection: rosapi's
``set_param``, Foxglove's ``setParameters``) is charged to that client, with its
value's size (``values.value_size``), until someone else sets it (the charge
moves to that client, or to nobody for in-process code and links), it is
deleted, or the client disconnects. Then what it still holds outlives it, as
rosbridge_suite's parameters do (D34), but is charged to *left behind*, one
share for every client that left: past it the oldest left behind go
(``Parameters``, docs/limits.md). A charge is one dict entry per parameter, so
charging and releasing cost what changes, not the store's size.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .values import ParameterStoreFullError

if TYPE_CHECKING:
    from collections.abc import Iterator

    from rwt_protocol.ports import ClientId

__all__ = ["LEFT_BEHIND", "Shares"]

LEFT_BEHIND = "<left behind>"
"""The holder of the parameters of clients that disconnected (never a client's id)."""


@dataclass
class _Share:
    """What one holder is charged: each key's size, oldest first."""

    sizes: dict[str, int] = field(default_factory=dict)
    bytes: int = 0


class Shares:
    """The charges of a store's parameters to clients (see the module text).

    Args:
        max_params: parameters one holder may be charged at most.
        max_bytes: bytes of values one holder may be charged at most.
    """

    def __init__(self, max_params: int, max_bytes: int) -> None:
        self.max_params = max_params
        self.max_bytes = max_bytes
        self._holder: dict[str, ClientId] = {}  # key -> who it is charged to
        self._shares: dict[ClientId, _Share] = {}

    def holder(self, key: str) -> ClientId | None:
        """Who ``key`` is charged to (a client id, ``LEFT_BEHIND``), or None."""
        return self._holder.get(key)

    def held(self, client: ClientId) -> tuple[int, int]:
        """``(parameters, bytes)`` charged to ``client``."""
        share = self._shares.get(client)
        return (0, 0) if share is None else (len(share.sizes), share.bytes)

    def check(self, client: ClientId, changes: dict[str, int | None]) -> None:
        """Refuse changes after which ``client`` would hold more than its share.

        ``changes``: each key ``client`` sets, with its new size, or None for a
        key it removes (a ROS 1 leaf its namespace replaces). A holder already
        past its share (a store made smaller) may still shrink.

        Raises:
            ParameterStoreFullError: ``client`` would hold more parameters or
                bytes than its share, and more than now.
        """
        share = self._shares.get(client) or _Share()
        count, size = len(share.sizes), share.bytes
        for key, new in changes.items():
            old = share.sizes.get(key)
            count += (new is not None) - (old is not None)
            size += (new or 0) - (old or 0)
        if count > self.max_params and count > len(share.sizes):
            raise ParameterStoreFullError(self._full(f"{self.max_params} parameters"))
        if size > self.max_bytes and size > share.bytes:
            raise ParameterStoreFullError(self._full(f"{self.max_bytes} bytes"))

    @staticmethod
    def _full(what: str) -> str:
        return (
            f"this client holds its share of the parameter store ({what}): "
            "delete some of the parameters it set first"
        )

    def charge(self, key: str, client: ClientId | None, size: int) -> None:
        """Charge ``key`` (of ``size`` bytes) to ``client``; None charges it to nobody."""
        self.release(key)
        if client is None:
            return
        share = self._shares.setdefault(client, _Share())
        share.sizes[key] = size
        share.bytes += size
        self._holder[key] = client

    def release(self, key: str) -> None:
        """``key`` is charged to nobody (it was deleted, or in-process code set it)."""
        client = self._holder.pop(key, None)
        if client is None:
            return
        share = self._shares[client]
        share.bytes -= share.sizes.pop(key)
        if not share.sizes and client != LEFT_BEHIND:
            del self._shares[client]

    def leave(self, client: ClientId) -> list[str]:
        """``client`` disconnected: what it held is left behind, its oldest first.

        Returns:
            The keys to delete so that what is left behind stays within one share,
            the oldest first (still charged: deleting them releases them).
        """
        share = self._shares.pop(client, None)
        left = self._shares.setdefault(LEFT_BEHIND, _Share())
        if share is not None:
            for key, size in share.sizes.items():
                left.sizes[key] = size
                self._holder[key] = LEFT_BEHIND
            left.bytes += share.bytes
        return list(self._over(left))

    def _over(self, left: _Share) -> Iterator[str]:
        count, size = len(left.sizes), left.bytes
        for key, key_size in left.sizes.items():
            if count <= self.max_params and size <= self.max_bytes:
                return
            yield key
            count -= 1
            size -= key_size

    def keys_of(self, client: ClientId) -> list[str]:
        """The keys charged to ``client``, oldest first."""
        share = self._shares.get(client)
        return [] if share is None else list(share.sizes)
