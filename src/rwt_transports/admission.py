"""First input first: a new connection's first frames go before later input of others.

A client that connects, subscribes and then makes an older client publish (it
tells it out of band) expects the message: its subscribe reached the server
first. But a new connection is not read until its task has started and its
reader has set up (accept, the stream's transport, the WebSocket response, the
session), and the kernel does not even report two sockets ready in the order
their bytes came; meanwhile the older connection's later publish is handled and
the new subscriber misses it.

So a starting connection holds a ``Ticket`` from the moment the server may read
it without waiting on the peer (plain TCP: accept; WebSocket: the upgrade
response) until its reader has handled its first input. A reader of any other
connection that got input asks, before handling it, whether a starting
connection has input waiting (queued, or readable in the kernel: one ``poll``
each) or is still being set up, and if so waits for it (``wait_for_new``).
Whatever the older connection got after the new one's first frames arrived is
then handled after them. A ticket counts for ``START_WAIT_S`` at most, and a
reader waits at most as long (docs/limits.md): a ticket is never waited on while
its connection waits for its peer, so the bound is a safety net, and a client
that connects and says nothing costs the others one ``poll`` per batch for that
time.

Per thread, as an event loop is (``anyio.Event`` belongs to one loop).
"""

from __future__ import annotations

import contextvars
import threading
from typing import TYPE_CHECKING

import anyio

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["START_WAIT_S", "Ticket", "current_ticket", "hold", "starting", "wait_for_new"]

START_WAIT_S = 0.5
"""Seconds a starting connection's ticket counts, and most a reader waits for tickets."""


class _Starting(threading.local):
    def __init__(self) -> None:
        self.tickets: set[Ticket] = set()  # held
        self.released: anyio.Event | None = None  # set at the next release


_state = _Starting()


class Ticket:
    """A starting connection whose first input is not handled yet.

    Until ``watch`` gives it a probe, the connection is being set up and counts
    as having input. ``release`` is idempotent.
    """

    __slots__ = ("_probe", "_since")

    def __init__(self) -> None:
        self._probe: Callable[[], bool] | None = None
        self._since = anyio.current_time()
        _state.tickets.add(self)

    @property
    def held(self) -> bool:
        """Whether the connection still has first input to handle."""
        return self in _state.tickets

    def serve(self) -> None:
        """Make this the current task's ticket (call it in the task serving the connection).

        Its reader, a child task, finds it with ``current_ticket``.
        """
        _CURRENT.set(self)

    def watch(self, probe: Callable[[], bool]) -> None:
        """The reader is ready: ``probe()`` tells whether input is waiting for it."""
        self._probe = probe

    def release(self) -> None:
        """The first input is handled (or the connection ended): readers of others go on."""
        state = _state
        if self not in state.tickets:
            return
        state.tickets.discard(self)
        if state.released is not None:
            state.released.set()
            state.released = None

    def _ahead(self, now: float) -> bool:
        """Whether input of this connection may have come before a reader's: wait for it."""
        if now - self._since > START_WAIT_S:
            self.release()  # a client that says nothing is not probed for ever
            return False
        probe = self._probe
        return probe is None or probe()


_CURRENT: contextvars.ContextVar[Ticket | None] = contextvars.ContextVar(
    "rwt_start_ticket", default=None
)


def hold() -> Ticket:
    """Take a ticket for a connection the server starts to read (``Ticket.serve`` next)."""
    return Ticket()


def current_ticket() -> Ticket | None:
    """The held ticket of the connection the current task serves, if any."""
    ticket = _CURRENT.get()
    return ticket if ticket is not None and ticket.held else None


def starting() -> bool:
    """Whether some connection is starting (cheap: readers ask it for every batch)."""
    return bool(_state.tickets)


async def wait_for_new() -> None:
    """Wait while a starting connection has input to handle first, at most ``START_WAIT_S``."""
    state = _state
    deadline = anyio.current_time() + START_WAIT_S
    while True:
        now = anyio.current_time()
        if now >= deadline or not any(ticket._ahead(now) for ticket in list(state.tickets)):
            return
        if state.released is None:
            state.released = anyio.Event()
        with anyio.move_on_after(deadline - now):
            await state.released.wait()
