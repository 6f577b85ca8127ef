"""First input first: a new connection's first frames go before later input of others.

A client that connects, subscribes and then makes an older client publish (it
tells it out of band) expects the message: its subscribe reached the server
first. But a new connection is not read until its task has started and its
reader has set up (accept, the stream's transport, the WebSocket response, the
session), and the kernel does not even report two sockets ready in the order
their bytes came; meanwhile the older connection's later publish is handled and
the new subscriber misses it.

So a starting connection holds a ``Ticket`` from the moment the server may read
it without waiting on the peer (plain TCP: accept; TLS: the end of its
handshake) until its reader has handled its first input; its probe
(``Ticket.watch``) is given as soon as the connection's channel exists where
the probe sees every byte waiting (``stream_sees_all``: a plain socket read by
the direct reader), else by its reader. A reader of any other connection that
got input asks, before handling it, whether a starting connection has input
waiting or is still being set up, and if so waits for it
(``Admission.wait_for_new``). Whatever the older connection got after the new
one's first frames arrived is then handled after them. Starting connections
wait so for the tickets taken before theirs (two clients that connect and then
talk to each other, as roslibjs test suites do). A ticket counts for
``START_WAIT_S`` at most, and a reader waits at most as long (docs/limits.md): a
ticket is never waited on while its connection waits for its peer, so the bound
is a safety net, and a client that connects and says nothing costs the others
one ``poll`` per batch for that time.

A WebSocket connection needs no ticket: its reader listens before the upgrade
response goes (``pump.ConnectionPump``'s ``hello``), so the peer's first frame,
sent after it, reaches a reader that waits, and the event loop reports it in
the order it arrived among every connection's input, whichever connection is
older (a page that opens its publisher first, then its subscribers, and
publishes once they subscribed, gets the message to them). It holds one only
for frames sent with the upgrade request, which wait in the parser. A TCP
client may send before the server accepted its connection, so there two new
connections' first frames go in the connections' order (docs/limits.md).

Whether input waits is told by the channel's probe (``stream_probe``): bytes in
the kernel (one ``poll``), decrypted TLS bytes not read yet, and the direct
reader's queue. Without the ``direct-read`` shortcut, anyio may hold a chunk it
read for a reader that was waiting and is woken but has not run yet; a probe
that cannot see such buffers says so (None), and the asking reader lets the loop
turn once before it looks again: the woken reader then runs first, as it was
scheduled first. So the order does not depend on a shortcut or on TLS.

The tickets are the server's (``Admission``, one per server and so per event
loop: ``anyio.Event`` belongs to one loop); a connection's reader finds its own
ticket through its task's context (``current_ticket``).
"""

from __future__ import annotations

import contextvars
import itertools
import select
from typing import TYPE_CHECKING

import anyio
import anyio.lowlevel
from anyio.abc import SocketAttribute
from anyio.streams.tls import TLSAttribute

if TYPE_CHECKING:
    from collections.abc import Callable

    from anyio.abc import ByteStream

    from ..direct import DirectReader

__all__ = [
    "START_WAIT_S",
    "Admission",
    "Ticket",
    "current_ticket",
    "stream_probe",
    "stream_sees_all",
]

START_WAIT_S = 0.5
"""Seconds a starting connection's ticket counts, and most a reader waits for tickets."""


_order = itertools.count()  # tickets in the order taken (any thread: count is atomic)


class Ticket:
    """A starting connection whose first input is not handled yet.

    Until ``watch`` gives it a probe, the connection is being set up and counts
    as having input (the transports give one when they take the ticket, so this
    lasts no loop turn). ``release`` is idempotent. Tickets are ordered by when
    they were taken (``Admission.hold``).
    """

    __slots__ = ("_admission", "_probe", "_seq", "_since")

    def __init__(self, admission: Admission) -> None:
        self._admission = admission
        self._probe: Callable[[], bool | None] | None = None
        self._since = anyio.current_time()
        self._seq = next(_order)
        admission.tickets.add(self)

    @property
    def held(self) -> bool:
        """Whether the connection still has first input to handle."""
        return self in self._admission.tickets

    def serve(self) -> None:
        """Make this the current task's ticket (call it in the task serving the connection).

        Its reader, a child task, finds it with ``current_ticket``.
        """
        _CURRENT.set(self)

    def watch(self, probe: Callable[[], bool | None]) -> None:
        """The reader is ready: ``probe()`` tells whether input is waiting for it.

        The probe answers None when input may wait where it cannot see (``stream_probe``).
        """
        self._probe = probe

    def release(self) -> None:
        """The first input is handled (or the connection ended): readers of others go on."""
        state = self._admission
        if self not in state.tickets:
            return
        state.tickets.discard(self)
        if state.released is not None:
            state.released.set()
            state.released = None

    def _ahead(self, now: float) -> bool | None:
        """Whether input of this connection may have come before a reader's: wait for it.

        None: the probe cannot see every buffer (``stream_probe``).
        """
        if now - self._since > START_WAIT_S:
            self.release()  # a client that says nothing is not probed for ever
            return False
        probe = self._probe
        return True if probe is None else probe()


_CURRENT: contextvars.ContextVar[Ticket | None] = contextvars.ContextVar(
    "rwt_start_ticket", default=None
)


def current_ticket() -> Ticket | None:
    """The held ticket of the connection the current task serves, if any."""
    ticket = _CURRENT.get()
    return ticket if ticket is not None and ticket.held else None


class Admission:
    """One server's starting connections: the tickets its readers wait for.

    Used on the server's event loop only. Memory: one entry per connection
    between its start and its first input handled (``START_WAIT_S`` at most).
    """

    def __init__(self) -> None:
        self.tickets: set[Ticket] = set()  # held
        self.released: anyio.Event | None = None  # set at the next release

    def hold(self) -> Ticket:
        """Take a ticket for a connection the server starts to read (``Ticket.serve`` next)."""
        return Ticket(self)

    def starting(self) -> bool:
        """Whether some connection is starting (cheap: readers ask it for every batch)."""
        return bool(self.tickets)

    async def wait_for_new(self, own: Ticket | None = None) -> None:
        """Wait while a starting connection has input to handle first, at most ``START_WAIT_S``.

        ``own``: the ticket of the reader's own connection if it is starting too;
        it then waits only for the tickets taken before it, so two starting
        connections never wait for each other.
        """
        deadline = anyio.current_time() + START_WAIT_S
        turned = False  # the loop turned once for probes that cannot see every buffer
        while True:
            now = anyio.current_time()
            if now >= deadline:
                return
            blind = False
            ahead = False
            for ticket in list(self.tickets):
                if ticket is own or (own is not None and ticket._seq > own._seq):
                    continue
                answer = ticket._ahead(now)
                if answer:
                    ahead = True
                    break
                blind = blind or answer is None
            if not ahead:
                if not blind or turned:
                    return
                turned = True  # a woken reader runs before this one's next step
                await anyio.lowlevel.checkpoint()
                continue
            if self.released is None:
                self.released = anyio.Event()
            with anyio.move_on_after(deadline - now):
                await self.released.wait()


def stream_sees_all(stream: ByteStream, reader: DirectReader | None) -> bool:
    """Whether ``stream_probe`` sees every byte waiting for the connection (never None).

    So with the direct reader on a plain socket: it reads anyio's queue too. A TLS
    stream, or one read through anyio's own ``receive``, may hold bytes it cannot see.
    """
    extra = getattr(stream, "extra", None)
    ssl_object = extra(TLSAttribute.ssl_object, None) if extra is not None else None
    return reader is not None and ssl_object is None


def stream_probe(stream: ByteStream, reader: DirectReader | None) -> Callable[[], bool | None]:
    """The probe of a socket stream's input (``Ticket.watch``), plain or TLS.

    Args:
        stream: the connection's anyio stream (a socket stream, or TLS over one).
        reader: its direct reader, when the ``direct-read`` shortcut serves it.

    Returns:
        a function answering True when input waits (in the kernel: one ``poll``;
        in the TLS object; in the direct reader's queue), False when none does,
        and None when none is seen but anyio may hold some for a woken reader
        (its own stream, without the direct reader).
    """
    extra = getattr(stream, "extra", None)  # anyio's typed attributes; None on a stand-in
    sock = extra(SocketAttribute.raw_socket, None) if extra is not None else None
    ssl_object = extra(TLSAttribute.ssl_object, None) if extra is not None else None
    # The direct reader sees anyio's queue, and only a plain socket has one.
    seen = reader is not None and ssl_object is None

    def probe() -> bool | None:
        if reader is not None and reader.input_pending():
            return True
        if ssl_object is not None and ssl_object.pending():
            return True
        if sock is None:  # no socket to ask
            return False if seen else None
        if sock.fileno() < 0:
            return True  # closed: its reader learns so at once
        poller = select.poll()
        poller.register(sock.fileno(), select.POLLIN)
        if poller.poll(0):
            return True
        return False if seen else None

    return probe
