"""Shared pieces of service calls and action goals: arguments, spawning, pending records."""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Generic, Protocol, TypeVar

from rwt_protocol.errors import FieldError, GraphError
from rwt_protocol.names import resolve_name
from rwt_protocol.ops.base import json_type_name

from .ratelog import EpisodeLog

if TYPE_CHECKING:
    from rwt_protocol.ports import ClientId

    from .clock import Clock
    from .types import Converted, MessageType, TypeRegistry

__all__ = [
    "LOCAL_PREFIX",
    "Offer",
    "ProviderTable",
    "Soon",
    "Spawner",
    "convert_args",
    "guarded",
    "is_local",
    "require_spawner",
]

LOCAL_PREFIX = "local:"
"""Participant ids of in-process code (the server's built-ins and embedding code)."""


def is_local(client: ClientId) -> bool:
    """Whether ``client`` is in-process code rather than a client connection."""
    return client.startswith(LOCAL_PREFIX)


logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message


def guarded(what: str, step: Callable[[], None]) -> None:
    """Run one step of a cleanup; an exception is logged (a bug) and the cleanup goes on.

    A client's disconnect releases many things (topics, services, goals, other
    callers' replies); one failing step must not leave the rest registered,
    a zombie service or action (docs/limits.md).
    """
    try:
        step()
    except Exception:
        _episodes.log(
            logging.ERROR, "cleanup_failed", "%s failed; the cleanup goes on", what, exc_info=True
        )


Spawner = Callable[[Callable[[], Awaitable[None]]], Callable[[], None]]
"""Runs an async job in the server's event loop; returns a function that cancels it.

The graph does no I/O and knows no event loop, so whoever runs it (the
server) lends it a spawner for async in-process services and actions while it
runs (``GraphCore.serving``)."""

Soon = Callable[[Callable[[], None]], object]
"""Calls a function once the event loop has finished its current turn (asyncio's
``loop.call_soon``): lent by the server with its spawner, for the graph's batched
delivery (docs/embedding.md, "Batched delivery")."""


def convert_args(msgtype: MessageType, args: object, *, path: str, now: float) -> Converted:
    """Build a request or goal from ``args`` (REF §4.4, D25).

    Args:
        msgtype: the request or goal type.
        args: an object (fields by name), a list (fields by position), or None.
        path: JSON path of ``args``, for error texts.
        now: wall-clock seconds, for header stamps.

    Returns:
        The converted message and the paths filled with defaults.

    Raises:
        FieldError: a value does not fit, too many positional values, or ``args``
            is neither object, array nor null.
    """
    if args is None:
        args = {}
    elif isinstance(args, list):
        names = [spec.name for spec in msgtype.fields]
        if len(args) > len(names):
            raise FieldError(path, f"expected at most {len(names)} arguments, got {len(args)}")
        args = dict(zip(names, args, strict=False))
    elif not isinstance(args, dict):
        raise FieldError(path, f"expected object or array, got {json_type_name(args)}")
    return msgtype.from_json(args, path=path, now=now)


def require_spawner(spawner: Spawner | None, what: str) -> Spawner:
    """Return the graph's spawner.

    Raises:
        GraphError: none is installed, so ``what`` (an async handler) cannot run.
    """
    if spawner is None:
        raise GraphError(f"{what} is async but no event loop runs this graph")
    return spawner


class Offer(Protocol):
    """An advertised service or action, as its table sees it."""

    name: str
    spelling: str
    owner: ClientId

    @property
    def type_name(self) -> str:
        """The canonical type of the offer (``std_srvs/srv/SetBool``)."""
        ...

    def end_all(self, reason: str) -> None:
        """Answer every caller waiting on this offer with a failure and ``reason`` (D4)."""

    def tell_lost(self, reason: str) -> None:
        """Tell a client provider that the offer was taken from it (D15)."""


E = TypeVar("E", bound=Offer)


class ProviderTable(Generic[E]):
    """Advertised services or actions by resolved name; each belongs to its provider.

    D15: a newer advertisement replaces an older one (whose
    callers fail and whose provider is told); only the owner may withdraw it.

    Args:
        kind: ``"service"`` or ``"action"``, for error texts.
        registry: resolves types.
        clock: wall time for header stamps.
        spawner: returns the graph's current spawner (``GraphCore.spawner``).
    """

    def __init__(
        self,
        kind: str,
        registry: TypeRegistry,
        clock: Clock,
        spawner: Callable[[], Spawner | None],
    ) -> None:
        self.kind = kind
        self.registry = registry
        self.clock = clock
        self._spawner = spawner
        self.entries: dict[str, E] = {}
        self.reserved: set[str] = set()
        """Resolved names no client may advertise even while nothing provides them."""
        self._refusals = EpisodeLog(logger)  # callers can trigger them at will
        self._owned: dict[ClientId, set[str]] = {}  # provider -> its names: release is O(held)
        self.on_change: Callable[[E, bool], None] | None = None
        """Told ``(entry, added)`` once the table has it or no longer has it (the change feed)."""

    def log_refusal(self, spelling: str, caller: str, reason: str) -> None:
        """Log that a client provider of ``spelling`` refused a request (busy, docs/limits.md).

        One line per provider name per episode, repeats counted (``EpisodeLog``):
        its callers decide how often this happens.
        """
        self._refusals.log(
            logging.WARNING,
            f"{self.kind}:{spelling}",
            "event=provider_busy %s=%s caller=%s reason=%r",
            self.kind,
            spelling,
            caller,
            reason,
        )

    def advertise(self, entry: E) -> None:
        """Add ``entry``, replacing an older one with the same name (D15).

        A client connection cannot replace an in-process provider (rosapi, the TF
        republisher, a service of the embedding program), nor take a name in
        ``reserved`` (rosapi's names of the other dialect): those names are the
        server's (docs/limits.md, reserved names).

        Raises:
            GraphError: a client tried to take a name of the server's.
        """
        old = self.entries.get(entry.name)
        if not is_local(entry.owner) and (
            entry.name in self.reserved or (old is not None and is_local(old.owner))
        ):
            raise GraphError(f"{self.kind} {entry.spelling} is reserved by the server")
        self.entries[entry.name] = entry
        if old is not None:
            self._disown(old)
        self._owned.setdefault(entry.owner, set()).add(entry.name)
        if self.on_change is not None:  # the old owner's removal, then the new one's addition
            if old is not None:
                self.on_change(old, False)
            self.on_change(entry, True)
        if old is not None:
            reason = f"{self.kind} {old.spelling} was replaced by a newer advertiser"
            old.end_all(reason)
            old.tell_lost(reason)

    def owned(self, client: ClientId, name: str) -> E:
        """The entry of ``name`` if ``client`` provides it.

        Raises:
            GraphError: no such entry, or another participant provides it.
        """
        entry = self.entries.get(resolve_name(name))
        if entry is None or entry.owner != client:
            raise GraphError(f"{self.kind} {name} is not advertised by this client")
        return entry

    def unadvertise(self, client: ClientId, name: str) -> None:
        """Remove an entry ``client`` owns; its callers fail (D15).

        Raises:
            GraphError: ``client`` does not provide ``name``.
        """
        entry = self.owned(client, name)
        del self.entries[entry.name]
        self._disown(entry)
        if self.on_change is not None:
            self.on_change(entry, False)
        entry.end_all(f"{self.kind} {entry.spelling} was unadvertised")

    def take_owned(self, client: ClientId) -> list[E]:
        """Remove and return every entry ``client`` provides (it left), in name order.

        Costs what ``client`` provides, not the size of the table.
        """
        taken = []
        for name in sorted(self._owned.pop(client, ())):
            entry = self.entries.get(name)
            if entry is not None and entry.owner == client:
                del self.entries[name]
                taken.append(entry)
                if self.on_change is not None:
                    self.on_change(entry, False)
        return taken

    def _disown(self, entry: E) -> None:
        names = self._owned.get(entry.owner)
        if names is not None:
            names.discard(entry.name)
            if not names:
                del self._owned[entry.owner]
