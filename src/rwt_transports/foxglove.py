"""Foxglove clients on the server's WebSocket listeners (docs/foxglove.md).

A client that offers ``foxglove.sdk.v1`` or ``foxglove.websocket.v1`` in its
handshake gets the Foxglove WebSocket protocol (``rwt_foxglove``) on the same
graph; one that offers neither gets rosbridge. ``FoxgloveOptions.port`` opens a
listener that speaks only Foxglove (foxglove_bridge's default port is 8765).

A Foxglove connection is admitted as any WebSocket connection (the server's
``open_session``: ``--max-connections``, the host shares, ``/connected_clients``)
and uses that session's client id in the graph; its rosbridge ops are never read.
"""

from __future__ import annotations

import logging
import uuid
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from rwt_foxglove import FoxgloveLimits, FoxgloveSession, Wakeup, run_foxglove
from rwt_protocol.shortcuts import enabled

if TYPE_CHECKING:
    from rwt_graph.core import GraphCore
    from rwt_graph.parameters.store import Parameters
    from rwt_protocol.server.access import AccessPolicy
    from rwt_protocol.server.session import Session

    from .websocket import FoxgloveServe, WebSocketChannel

__all__ = ["FoxgloveOptions", "foxglove_server"]

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
) -> FoxgloveServe:
    """The function that runs each accepted Foxglove connection of one server.

    Args:
        graph: the served graph's core.
        access: the server's access globs (a topic a client may not see is not advertised).
        limits: each client's bounds.
        params: the graph's parameters (``Graph.params``); None: no parameters capability.
    """
    session_id = uuid.uuid4().hex  # one per server run: clients tell a restart by it

    async def serve(channel: WebSocketChannel, session: Session, subprotocol: str) -> None:
        wakeup = Wakeup()
        foxglove = FoxgloveSession(
            graph,
            session.client_id,
            session_id=session_id,
            access=access,
            limits=limits,
            on_output=wakeup.set,
            params=params,
        )
        logger.info("event=foxglove client=%s subprotocol=%s", session.client_id, subprotocol)
        # ``deferred-send`` (rwt_protocol/shortcuts.py): off, the writer task writes everything
        direct = channel.abilities.send_now and enabled("deferred-send")
        await run_foxglove(channel, foxglove, wakeup, direct=direct)

    return serve
