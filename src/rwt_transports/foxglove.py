"""Foxglove clients on the server's WebSocket listeners (docs/foxglove.md).

A client that offers ``foxglove.sdk.v1`` or ``foxglove.websocket.v1`` in its
handshake gets the Foxglove WebSocket protocol (``rwt_foxglove``) on the same
graph; one that offers neither gets rosbridge. ``FoxgloveOptions.port`` opens a
listener that speaks only Foxglove (foxglove_bridge's default port is 8765).

A Foxglove connection is admitted as any WebSocket connection (the server's
``open_session``: ``--max-connections``, the host shares, ``/connected_clients``)
and uses that session's client id in the graph; its rosbridge ops are never read.

With an authenticator (``--auth-secret-file``) a Foxglove client, which has no
``auth`` op and whose user can only type a URL, carries the ``auth`` op's fields
in its URL's query string (``rwt_protocol.auth.auth_query``); ``url_token_gate``
checks them with the same authenticator during the handshake and refuses the
connection (HTTP 401 without a token, 403 with a bad one) before any session (D33).
"""

from __future__ import annotations

import logging
import os
import uuid
from dataclasses import dataclass, field
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

from rwt_foxglove import AssetRoots, FoxgloveLimits, FoxgloveSession, Wakeup, run_foxglove
from rwt_protocol.auth import auth_from_query
from rwt_protocol.errors import RemoteProtocolError

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

    from rwt_graph.core import GraphCore
    from rwt_graph.parameters.store import Parameters
    from rwt_protocol.auth import Authenticator
    from rwt_protocol.server.access import AccessPolicy
    from rwt_protocol.server.session import Session

    from .websocket import FoxgloveGate, FoxgloveServe, WebSocketChannel

__all__ = ["FoxgloveOptions", "foxglove_server", "url_token_gate"]

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
        assets: answer ``fetchAsset`` (the ``assets`` capability) from
            ``package_paths``, then ``ROS_PACKAGE_PATH`` and ``AMENT_PREFIX_PATH``'s
            share folders (``rwt serve --assets``; off where none of them exists).
        package_paths: directories holding ROS packages (``--package-path``).
    """

    on_rosbridge_port: bool = True
    port: int | None = None
    limits: FoxgloveLimits = field(default_factory=FoxgloveLimits)
    assets: bool = False
    package_paths: Sequence[Path] = ()


def foxglove_server(
    graph: GraphCore,
    access: AccessPolicy,
    options: FoxgloveOptions,
    params: Parameters | None = None,
) -> FoxgloveServe:
    """The function that runs each accepted Foxglove connection of one server.

    Args:
        graph: the served graph's core.
        access: the server's access globs (a topic a client may not see is not advertised).
        options: each client's bounds (``limits``) and where assets are found
            (read once, with the environment's ROS paths, here).
        params: the graph's parameters (``Graph.params``); None: no parameters capability.
    """
    limits = options.limits
    assets = (
        AssetRoots.from_environment(options.package_paths, os.environ) if options.assets else None
    )
    session_id = uuid.uuid4().hex  # one per server run: clients tell a restart by it

    async def serve(channel: WebSocketChannel, session: Session, subprotocol: str) -> None:
        if not session.authenticated:  # an authenticator, and no gate admitted the client
            logger.warning(
                "event=foxglove_refused client=%s reason='not authenticated'", session.client_id
            )
            return
        wakeup = Wakeup()
        foxglove = FoxgloveSession(
            graph,
            session.client_id,
            session_id=session_id,
            access=access,
            limits=limits,
            on_output=wakeup.set,
            params=params,
            assets=assets is not None,
        )
        logger.info("event=foxglove client=%s subprotocol=%s", session.client_id, subprotocol)
        await run_foxglove(channel, foxglove, wakeup, assets=assets)

    return serve


NO_TOKEN = "authentication required: add the token to the URL (docs/foxglove.md)"
"""The reason of a Foxglove handshake refused for want of a URL token (HTTP 401)."""

BAD_TOKEN = "authentication failed"
"""The reason of a Foxglove handshake whose URL token was refused (HTTP 403)."""


def url_token_gate(authenticator: Authenticator) -> FoxgloveGate:
    """Admit Foxglove handshakes whose URL carries a token ``authenticator`` admits.

    The token is the ``auth`` op's fields as query parameters (``mac``, ``client``,
    ``dest``, ``rand``, ``t``, ``level``, ``end``; ``rwt_protocol.auth.auth_query``),
    checked as an ``auth`` op is: the same MAC, the same time window.

    Args:
        authenticator: the server's (``rosauth_authenticator``, or embedding code's).

    Returns:
        The gate: given the request path and the peer, (401, ``NO_TOKEN``) for a
        URL without ``mac``, (403, reason) for an unreadable or refused token (the
        reason says only what the client sent wrong; the authenticator logs its
        own), None to accept.
    """

    def refusal(path: str, peer: str) -> tuple[int, str] | None:
        try:
            op = auth_from_query(urlsplit(path).query)
        except (RemoteProtocolError, ValueError) as exc:
            return 403, f"{BAD_TOKEN}: {exc}"
        if op is None:
            return 401, NO_TOKEN
        try:
            admitted = authenticator(op, peer)
        except Exception:  # embedding code's check failed: a refusal, logged
            logger.exception("event=authenticator_failed peer=%s", peer)
            admitted = False
        if not admitted:
            return 403, BAD_TOKEN
        logger.info("event=auth_ok peer=%s level=%s via=foxglove_url", peer, op.level)
        return None

    return refusal
