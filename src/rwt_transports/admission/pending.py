"""What a socket holds before its request is admitted: bytes, a count and a turn per host (D58).

A socket on the WebSocket port is read before anything admits it: an HTTP request
(the HTTP API, ``/mcp``, ``/webrtc``, ``/version``; ``http.endpoint.open_request``,
the one reader) is read whole, head and body, before its endpoint asks the server for
a session, a slot or a ticket (``GraphServer.open_session``, ``take_slot``, ``admit``,
``join_socket``), and a WebSocket upgrade (or the console's request) is read up to its
end before the handshake's checks (``websocket._handshake``). Without a bound here, one
address with 250 sockets, each sending a 10 MiB body short of its last byte, made the
server hold 3 GB outside every budget. What such a socket holds is its
``PendingSocket``, one per accepted socket (``current_socket``), under the server's
``PendingRequests``:

- **bytes**: what the reader keeps (a request's head, its body: a declared
  ``Content-Length`` is charged before a byte of the body is read, a chunked body as
  it grows) is charged to the server's budget of input still arriving
  (``--max-fragment-memory``, ``FragmentBudget``), which counts in the memory budget
  (``--memory-budget``, D44) as every client's input does; a charge that does not fit
  there is refused with 503. A host's sockets together hold at most
  ``1 / HOST_INPUT_SHARE`` of that budget: past it, 429.
- **count**: a host has at most ``--max-connections-per-host`` HTTP requests read and
  not admitted at once, from the first (as MCP sessions, D40): one more gets 429.
- **turns**: a host's requests are parsed one slice at a time (``PendingSocket.turn``),
  and what its refused sockets still send is read one read at a time (``wait_turn``),
  so that however many sockets a host has, they take one reader's share of the event
  loop (``http.endpoint.READ_SLICE_EVENTS``).

Both refusals carry ``Retry-After: RETRY_AFTER_S`` (docs/limits.md). Everything a
socket holds here is given back when it is admitted (``PendingSocket.admit``: its
session or slot bounds it from then on) or closed (``release``).
"""

from __future__ import annotations

import contextvars
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import anyio

from .shares import address_of

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

    from rwt_protocol.framing.fragments import FragmentBudget

    from .shares import HostPrefixes

__all__ = [
    "HOST_INPUT_SHARE",
    "RETRY_AFTER_S",
    "PendingRefusal",
    "PendingRequests",
    "PendingSocket",
    "current_socket",
    "serve_socket",
]

HOST_INPUT_SHARE: Final = 4
"""A host's sockets not yet admitted hold at most ``1 / 4`` of ``--max-fragment-memory``
(64 MiB of the default 256 MiB), so that one host never fills it for the others."""

RETRY_AFTER_S: Final = 1
"""The ``Retry-After`` of a request refused for what the pending requests hold, seconds."""


@dataclass(frozen=True, slots=True)
class PendingRefusal:
    """Why a request not yet admitted is refused: an HTTP status (429, 503) and a text."""

    status: int
    text: str


class _Host:
    """What the sockets of one host hold: bytes, requests being read, its parse turn."""

    __slots__ = ("bytes", "requests", "sockets", "turn")

    def __init__(self) -> None:
        self.bytes = 0
        self.requests = 0
        self.sockets = 0
        self.turn = anyio.Lock(fast_acquire=True)


class PendingRequests:
    """Every socket of one server not yet admitted, by host (the module's text; D58).

    Args:
        budget: the server's budget of input still arriving (``--max-fragment-memory``),
            which counts in its memory budget (D44); None: bytes are not bounded.
        prefixes: which addresses are one host (``--host-prefix-v4``, ``-v6``).
        per_host: the most requests one host may have read and not admitted at once
            (``--max-connections-per-host``).
    """

    def __init__(
        self,
        budget: FragmentBudget | None,
        prefixes: HostPrefixes,
        per_host: int,
    ) -> None:
        self.budget = budget
        self.prefixes = prefixes
        self.per_host = per_host
        self._hosts: dict[str, _Host] = {}

    @property
    def host_share(self) -> int | None:
        """The bytes one host's sockets may hold together; None: no budget."""
        return None if self.budget is None else self.budget.limit // HOST_INPUT_SHARE

    def socket(self, peer: str) -> PendingSocket:
        """The record of a socket accepted from ``peer`` (``HOST:PORT``); ``release`` it."""
        host = self.prefixes.host(address_of(peer))
        record = self._hosts.get(host)
        if record is None:
            record = self._hosts[host] = _Host()
        record.sockets += 1
        return PendingSocket(self, host, record)

    def held(self, host: str) -> int:
        """Bytes the sockets of ``host`` (a host as ``HostPrefixes.host`` names it) hold."""
        record = self._hosts.get(host)
        return 0 if record is None else record.bytes

    def reading(self, host: str) -> int:
        """Requests of ``host`` read and not admitted now."""
        record = self._hosts.get(host)
        return 0 if record is None else record.requests

    def _grow(self, record: _Host, growth: int) -> PendingRefusal | None:
        """Charge ``growth`` more bytes to ``record``'s host, or say why not."""
        share = self.host_share
        if share is not None and record.bytes + growth > share:
            return PendingRefusal(
                429,
                f"this host's requests being read hold {record.bytes} bytes, and the server "
                f"keeps at most {share} for one host (a quarter of --max-fragment-memory): "
                "try again later",
            )
        budget = self.budget
        if budget is not None and not budget.take(growth):
            return PendingRefusal(
                503,
                f"the server holds {budget.limit} bytes of requests and messages still "
                "arriving already (--max-fragment-memory): try again later",
            )
        record.bytes += growth
        return None

    def _shrink(self, record: _Host, fewer: int) -> None:
        record.bytes -= fewer
        if self.budget is not None:
            self.budget.give(fewer)

    def _drop(self, host: str, record: _Host) -> None:
        """Forget ``host`` once none of its sockets is pending (nothing waits for its turn)."""
        record.sockets -= 1
        if record.sockets <= 0 and self._hosts.get(host) is record:
            del self._hosts[host]


class PendingSocket:
    """One accepted socket until it is admitted or closed: what it holds (the module's text).

    Attributes:
        host: its host, as ``HostPrefixes.host`` names it.
        admitted: the server admitted it (a session, a slot, a ticket): it holds
            nothing here any more.
        scope: the cancel scope of its handshake's deadline (the server's).
    """

    __slots__ = ("_counted", "_held", "_owner", "_record", "admitted", "host", "scope")

    def __init__(self, owner: PendingRequests, host: str, record: _Host) -> None:
        self._owner = owner
        self._record: _Host | None = record
        self.host = host
        self._held = 0
        self._counted = False
        self.admitted = False
        self.scope = anyio.CancelScope()

    def hold(self, size: int) -> PendingRefusal | None:
        """Charge ``size`` bytes in all (less than before gives the rest back).

        Returns:
            None when charged; else why not (429: the host's share; 503: the server's
            budgets), and the charge is unchanged. Nothing is charged once admitted.
        """
        record = self._record
        if record is None or size == self._held:
            return None
        if size < self._held:
            self._owner._shrink(record, self._held - size)
        else:
            refusal = self._owner._grow(record, size - self._held)
            if refusal is not None:
                return refusal
        self._held = size
        return None

    def enter(self) -> PendingRefusal | None:
        """Count the socket's request as one its host reads; 429 past the host's count."""
        record = self._record
        if record is None or self._counted:
            return None
        per_host = self._owner.per_host
        if record.requests >= per_host:
            return PendingRefusal(
                429,
                f"this host has {record.requests} requests being read already "
                f"(--max-connections-per-host {per_host}): try again later",
            )
        record.requests += 1
        self._counted = True
        return None

    @asynccontextmanager
    async def turn(self) -> AsyncIterator[None]:
        """Hold the host's turn to parse: its sockets parse one slice at a time."""
        record = self._record
        if record is None:
            yield
            return
        async with record.turn:
            yield

    async def wait_turn(self) -> None:
        """Wait for the host's turn, and pass it on (a refused socket's next read)."""
        async with self.turn():
            pass

    def refused(self) -> None:
        """Its request was refused: give back its bytes and its place in the host's count.

        It keeps its place in the host's turns until it is released: what the refused
        socket still reads, and drops, takes turns with the host's other sockets.
        """
        record = self._record
        if record is None:
            return
        self.hold(0)
        if self._counted:
            record.requests -= 1
            self._counted = False

    def admit(self) -> None:
        """The server admitted the socket: give back what it holds here (idempotent)."""
        self.admitted = True
        self.release()

    def release(self) -> None:
        """The socket closed: give back what it holds here (idempotent)."""
        record = self._record
        if record is None:
            return
        self.refused()
        self._record = None
        self._owner._drop(self.host, record)


_CURRENT: contextvars.ContextVar[PendingSocket | None] = contextvars.ContextVar(
    "rwt_pending_socket", default=None
)


def current_socket() -> PendingSocket | None:
    """The socket the current connection task serves, while not admitted; else None.

    None also for a request that came another way than an accepted socket (one
    another worker passed here: it was bounded where it was read).
    """
    socket = _CURRENT.get()
    return None if socket is None or socket.admitted else socket


def serve_socket(socket: PendingSocket) -> None:
    """Make ``socket`` the current task's (the server's, once per accepted socket)."""
    _CURRENT.set(socket)
