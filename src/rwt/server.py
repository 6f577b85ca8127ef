"""The parts of ``rwt.ServerConfig`` and an embedded server's hooks (docs/server.md).

Listener options (``WebSocketOptions``, ``UdpOptions``, the web console's
``ConsoleSite``), access rules (``AccessPolicy`` over a ``Family`` of names and a
topic's ``TopicUse``, and the ``AccessDeniedError`` a client gets), authentication
(the ``Auth`` op an authenticator gets, ``rosauth_authenticator``; ``rosauth_op`` signs one and
``auth_query`` puts it in a Foxglove client's URL), the in-process client connection
(``MemoryConnection``), the allocator tuning ``rwt serve`` does, the shortcuts on
and off in this process (``shortcut_report``, docs/shortcuts.md), and ``Compat``, the
drop-in mode for clients written against rosbridge_suite (docs/differences.md), and
the Foxglove WebSocket listener's options (``FoxgloveOptions``, ``FoxgloveLimits``;
docs/foxglove.md), WebRTC signalling's (``WebRtcOptions``, docs/webrtc.md), the
MCP endpoint's (``McpOptions``, docs/mcp.md; ``McpSiblings``, a worker's place among
the others of ``--workers``; ``Placement``, its place for ``--placement topic``, D57) and
the HTTP API's (``HttpApiOptions``,
docs/http.md; ``ServerConfig.http_options["http"]``), and ``Admitted``, the ticket of
a connection admitted without a session (``GraphServer.admit``).

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_console.site import ConsoleSite
    from rwt_foxglove.session import FoxgloveLimits
    from rwt_http.session import HttpApiOptions
    from rwt_protocol.auth import auth_query, rosauth_op
    from rwt_protocol.ops import Auth
    from rwt_protocol.runtime.access import AccessDeniedError, AccessPolicy, Family, TopicUse
    from rwt_protocol.server.compat import Compat
    from rwt_protocol.shortcuts import shortcut_report
    from rwt_transports.foxglove import FoxgloveOptions
    from rwt_transports.host import Admitted
    from rwt_transports.http.mcp_options import McpOptions
    from rwt_transports.http.mcp_siblings import McpSiblings
    from rwt_transports.memory import MemoryConnection
    from rwt_transports.process.allocator import tune_allocator
    from rwt_transports.server import rosauth_authenticator
    from rwt_transports.udp.transport import UdpOptions
    from rwt_transports.webrtc.signalling import WebRtcOptions
    from rwt_transports.websocket import WebSocketOptions
    from rwt_transports.workers.placement import Placement

__all__ = [
    "AccessDeniedError",
    "AccessPolicy",
    "Admitted",
    "Auth",
    "Compat",
    "ConsoleSite",
    "Family",
    "FoxgloveLimits",
    "FoxgloveOptions",
    "HttpApiOptions",
    "McpOptions",
    "McpSiblings",
    "MemoryConnection",
    "Placement",
    "TopicUse",
    "UdpOptions",
    "WebRtcOptions",
    "WebSocketOptions",
    "auth_query",
    "rosauth_authenticator",
    "rosauth_op",
    "shortcut_report",
    "tune_allocator",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
