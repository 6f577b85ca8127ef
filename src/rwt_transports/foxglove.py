"""Foxglove clients on the server's WebSocket listeners (docs/foxglove.md).

A client that offers ``foxglove.sdk.v1`` or ``foxglove.websocket.v1`` in its
handshake gets the Foxglove WebSocket protocol (``rwt_foxglove``) on the same
graph; one that offers neither gets rosbridge. ``FoxgloveOptions.port`` opens a
listener that speaks only Foxglove (foxglove_bridge's default port is 8765).

A Foxglove connection is admitted as any WebSocket connection (the server's
``open_session``: ``--max-connections``, the host shares, ``/connected_clients``)
and uses that session's client id in the graph; its rosbridge ops are never read.

Its queue takes part in the server's flow control as a rosbridge connection's
outbox does (``FoxgloveOutlet``, docs/limits.md "Backpressure"): a publishing
connection's reader, or a link's deliveries, whose batch filled the queue of a
Foxglove client past half its bounds waits while that client reads, within its
hold budget; a client that does not read is found slow and left to drop its
own oldest data. A publisher in the server's process is never held.
"""

from __future__ import annotations

import logging
import uuid
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import anyio

from rwt_foxglove import FoxgloveLimits, FoxgloveSession, Wakeup, run_foxglove
from rwt_protocol.shortcuts import enabled

from .holding import Held

if TYPE_CHECKING:
    from rwt_graph.core import GraphCore
    from rwt_graph.parameters.store import Parameters
    from rwt_protocol.server.access import AccessPolicy
    from rwt_protocol.server.session import Session

    from .flow import FlowControl
    from .websocket import FoxgloveServe, WebSocketChannel

__all__ = ["FoxgloveOptions", "FoxgloveOutlet", "foxglove_server"]

logger = logging.getLogger("rwt.foxglove")


@dataclass(frozen=True)
class FoxgloveOptions:
    """Where the server answers Foxglove clients.

    Attributes:
        on_rosbridge_port: answer the Foxglove subprotocols on the rosbridge
            WebSocket port (``rwt serve --no-foxglove``: off).
        port: a WebSocket port that speaks only Foxglove (``--foxglove-port``;
            0 picks a free one; None: no such listener). A client there that
            offers no Foxglove subprotocol is refused with HTTP 400.
        limits: each Foxglove client's bounds (docs/limits.md).
    """

    on_rosbridge_port: bool = True
    port: int | None = None
    limits: FoxgloveLimits = field(default_factory=FoxgloveLimits)


def foxglove_server(
    graph: GraphCore,
    access: AccessPolicy,
    limits: FoxgloveLimits,
    params: Parameters | None = None,
    flow: FlowControl[Held] | None = None,
) -> FoxgloveServe:
    """The function that runs each accepted Foxglove connection of one server.

    Args:
        graph: the served graph's core.
        access: the server's access globs (a topic a client may not see is not advertised).
        limits: each client's bounds.
        params: the graph's parameters (``Graph.params``); None: no parameters capability.
        flow: the server's flow control, which each client's queue takes part in;
            None: publishers never wait for a Foxglove client.
    """
    session_id = uuid.uuid4().hex  # one per server run: clients tell a restart by it

    async def serve(channel: WebSocketChannel, session: Session, subprotocol: str) -> None:
        wakeup = Wakeup()
        outlet: FoxgloveOutlet | None = None

        def on_output() -> None:
            wakeup.set()
            if flow is not None and outlet is not None and flow.in_batch:
                outlet.note_output(flow)

        foxglove = FoxgloveSession(
            graph,
            session.client_id,
            session_id=session_id,
            access=access,
            limits=limits,
            on_output=on_output,
            params=params,
        )
        if flow is not None:
            outlet = FoxgloveOutlet(foxglove, channel, limits)
            flow.open_connection(
                outlet, session.peer, session.config.hold_budget_s, outlet.water_marks
            )
            wakeup.on_sent = outlet.sent
        logger.info("event=foxglove client=%s subprotocol=%s", session.client_id, subprotocol)
        # ``deferred-send`` (rwt_protocol/shortcuts.py): off, the writer task writes everything
        direct = channel.abilities.send_now and enabled("deferred-send")
        try:
            await run_foxglove(channel, foxglove, wakeup, direct=direct)
        finally:
            if outlet is not None:
                outlet.close()  # readers waiting for it go on

    return serve


class FoxgloveOutlet(Held):
    """A Foxglove client's queue as the server's flow control sees it (the module's text).

    Its fill is counted in bytes, a message counting at least its share of the
    byte bound (``max_queue_bytes / max_queue_messages``), so that either bound
    congests: the watermarks are half and a quarter of ``max_queue_bytes``.

    Args:
        session: the client's session.
        channel: its connection (the socket's send queue tells progress).
        limits: its bounds.
    """

    def __init__(
        self, session: FoxgloveSession, channel: WebSocketChannel, limits: FoxgloveLimits
    ) -> None:
        super().__init__()
        self._session = session
        self._channel = channel
        self._per_message = max(1, limits.max_queue_bytes // max(1, limits.max_queue_messages))
        self.water_marks = (limits.max_queue_bytes // 2, limits.max_queue_bytes // 4)
        self._closed = False

    def fill(self) -> int:
        """The queue's fill in bytes (each message at least its share of the byte bound)."""
        session = self._session
        return max(session.queued_bytes, session.queued_messages * self._per_message)

    def note_output(self, flow: FlowControl[Held]) -> None:
        """Output was queued during a batch: the batch congested it if it is past its mark."""
        if not self._closed and flow.congests(self, self.fill()):
            flow.note_congested(self, anyio.current_time())

    def sent(self) -> None:
        """A batch went to the socket: the client makes progress (wakes held readers)."""
        self.note_take(self._session.queued_bytes == 0)

    def close(self) -> None:
        """The connection ended: nobody waits for it any more."""
        self._closed = True
        self.note_take(True)

    def over_water(self, *, own: bool, mark: int) -> bool:
        """Whether its fill is over ``mark`` (never for its own reader, which is no pump)."""
        return not own and not self._closed and self.fill() > mark

    def backlog_bytes(self) -> int:
        """What the client has yet to read: its queue and the socket's send queue."""
        return self._session.queued_bytes + (self.unsent_bytes() or 0)

    def unsent_bytes(self) -> int | None:
        """Bytes the socket's kernel still holds for the client (sendqueue.py)."""
        return self._channel.unsent_bytes()
