"""The Foxglove WebSocket protocol as a front end of the server (docs/foxglove.md).

A client that offers ``foxglove.sdk.v1`` or ``foxglove.websocket.v1`` in its
handshake gets the Foxglove protocol (``rwt_foxglove``) on the same graph; one that
offers neither gets rosbridge. ``FoxgloveOptions.port`` opens a listener that
speaks only Foxglove (foxglove_bridge's default port is 8765).

A Foxglove connection is one connection of the server like any other: admitted
the same way (``--max-connections``, the host shares, ``/connected_clients``), run
by the same pump under the same per-client rules (``ClientRules``: the send
buffer, the slow-consumer rule, ``--max-subscriptions``, ``--max-pending-calls``,
``--call-timeout``, ``--idle-timeout``, the hold budget) and flow control;
``foxglove_frontend`` only says how its session is made, and
``frontends_registry.FOXGLOVE`` is its entry in the registry. With an authenticator its clients
prove who they are with a URL token (``AuthMode.URL_TOKEN``,
``rwt_protocol.credentials``).
"""

from __future__ import annotations

import os
import uuid
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from rwt_foxglove import SUBPROTOCOLS, AssetRoots, FoxgloveLimits, FoxgloveSession
from rwt_protocol.errors import ConfigError

from .frontends import AuthMode, FrontEnd

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

    from rwt_graph.parameters.store import Parameters
    from rwt_graph.port import GraphFront
    from rwt_protocol.runtime.request import SessionRequest

    from .host import FrontEndHost

__all__ = ["FoxgloveOptions", "foxglove_for", "foxglove_frontend"]


@dataclass(frozen=True)
class FoxgloveOptions:
    """Where the server answers Foxglove clients.

    Attributes:
        on_rosbridge_port: answer the Foxglove subprotocols on the rosbridge
            WebSocket port (``rwt serve --no-foxglove``: off).
        port: a WebSocket port that speaks only Foxglove (``--foxglove-port``;
            0 picks a free one; None: no such listener). A client there that
            offers no Foxglove subprotocol is refused with HTTP 400.
        limits: the Foxglove section of each client's bounds (docs/limits.md); the
            rest are the server's per-client rules (``ServerConfig.session``).
        assets: answer ``fetchAsset`` (the ``assets`` capability) from
            ``package_paths``, then ``ROS_PACKAGE_PATH`` and ``AMENT_PREFIX_PATH``'s
            share folders (``rwt serve --assets``; off where none of them exists).
        package_paths: directories holding ROS packages (``--package-path``).
        show_plumbing: clients see rwt's own helpers too (rosapi's services,
            ``/client_count``, ``/connected_clients``, the TF republisher) and
            their nodes (``--foxglove-show-plumbing``); by default they see the
            robot's topics, services and nodes only, the nodes of client
            connections included (D47).
    """

    on_rosbridge_port: bool = True
    port: int | None = None
    limits: FoxgloveLimits = field(default_factory=FoxgloveLimits)
    assets: bool = False
    package_paths: Sequence[Path] = ()
    show_plumbing: bool = False


def foxglove_frontend(
    graph: GraphFront, options: FoxgloveOptions, params: Parameters | None = None
) -> FrontEnd:
    """The Foxglove protocol's front end for one server.

    Args:
        graph: the served graph's core.
        options: the Foxglove section of the clients' bounds and where assets are
            found (read once, with the environment's ROS paths, here).
        params: the graph's parameters (``Graph.params``); None: no parameters capability.
    """
    assets = (
        AssetRoots.from_environment(options.package_paths, os.environ) if options.assets else None
    )
    session_id = uuid.uuid4().hex  # one per server run: clients tell a restart by it

    def make_session(request: SessionRequest) -> FoxgloveSession:
        return FoxgloveSession(
            graph,
            request.client_id,
            session_id=session_id,
            config=request.rules,
            limits=options.limits,
            on_output=request.on_output,
            peer=request.peer,
            on_closed=request.on_closed,
            params=params,
            assets=assets,
            show_plumbing=options.show_plumbing,
            memory=request.memory,
        )

    return FrontEnd("foxglove", SUBPROTOCOLS, make_session, AuthMode.URL_TOKEN)


def foxglove_for(host: FrontEndHost, options: object) -> FrontEnd:
    """The Foxglove front end of ``host``'s graph (``frontends_registry.FOXGLOVE``).

    Raises:
        ConfigError: ``options`` is not a ``FoxgloveOptions``.
    """
    if not isinstance(options, FoxgloveOptions):
        raise ConfigError(
            f"Foxglove's options must be FoxgloveOptions, not {type(options).__name__}"
        )
    return foxglove_frontend(host.graph.port, options, host.graph.params)
