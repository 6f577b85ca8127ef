"""The one registry of the server's front ends: every protocol and way in it serves.

A front end is found here by what selects it (``frontends``):

- a WebSocket subprotocol in the handshake (``SOCKET_FRONTENDS``: Foxglove's,
  ``FOXGLOVE``); a client that offers none gets the default, rosbridge
  (``rosbridge_frontend``, ``rosbridge``);
- a WebRTC data channel's label: rosbridge's ``rosbridge`` and its lossy
  ``rosbridge-lossy`` (``rosbridge.DATA_CHANNEL_LABEL``, ``LOSSY_CHANNEL_LABEL``,
  D36), or a registered protocol's (``FrontEnd.labels``); any other label is refused;
- an HTTP path on the WebSocket port (``HTTP_FRONTENDS``): ``/version``
  (``VERSION``), WebRTC's signalling (``WEBRTC``), MCP (``MCP``), the HTTP API
  (``HTTP_API``).

Each entry says where ``ServerConfig`` holds its options and makes its front end
for a server typed as ``host.FrontEndHost``, the interface every front end is
written against: the server (``GraphServer``) makes each from here and knows none
by name, and no front end knows the server. ``ServerConfig.http_options`` gives an
HTTP front end its options, or None to turn it off. Adding a front end is its own
package, its transport module and an entry here (docs/architecture.md, "How to
add").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from rwt_http import HttpApiOptions

from .foxglove import foxglove_for
from .frontends import AuthMode, FrontEnd
from .http.api import API_PATHS, http_api_endpoint
from .http.mcp_options import MCP_PATH, METADATA_PATH
from .http.version import VERSION_PATH, version_endpoint
from .rosbridge import rosbridge_frontend
from .webrtc.signalling import WEBRTC_PATH

if TYPE_CHECKING:
    from collections.abc import Callable

    from .config import ServerConfig
    from .host import FrontEndHost
    from .http.endpoint import HttpEndpoint

__all__ = [
    "FOXGLOVE",
    "HTTP_API",
    "HTTP_FRONTENDS",
    "MCP",
    "SOCKET_FRONTENDS",
    "VERSION",
    "WEBRTC",
    "HttpFrontEnd",
    "SocketFrontEnd",
    "mcp_endpoint",
    "rosbridge_frontend",
    "webrtc_endpoint",
]


@dataclass(frozen=True, slots=True)
class HttpFrontEnd:
    """One front end of HTTP requests on the WebSocket port (docs/architecture.md).

    Attributes:
        name: its name in logs and in ``ServerConfig.http_options``.
        paths: the paths (or path prefixes ending in ``/``) its endpoint claims.
        make_endpoint: its endpoint for a server and its options: an
            ``HttpEndpoint`` that claims and answers the requests; it admits
            each through the server (``FrontEndHost.admit``, ``open_session``)
            and checks its clients' proofs with ``FrontEndHost.entry``.
        options: its options when the configuration names none; None: off.
        auth: how its clients prove who they are.
        transport: the transport its sessions run on, when it is one of its own
            (``webrtc``), for ``GET /version``'s list.
        configured: where ``ServerConfig`` holds its options when it has a field
            of its own (``ServerConfig.webrtc``); ``ServerConfig.http_options``
            by its name comes first.
    """

    name: str
    paths: tuple[str, ...]
    make_endpoint: Callable[[FrontEndHost, object], HttpEndpoint]
    options: object = None
    auth: AuthMode = AuthMode.BEARER
    transport: str | None = None
    configured: Callable[[ServerConfig], object] | None = None

    def options_in(self, config: ServerConfig) -> object:
        """Its options under ``config``: ``http_options[name]``, its field, or the default.

        None: it is off.
        """
        if self.name in config.http_options:
            return config.http_options[self.name]
        if self.configured is not None:
            return self.configured(config)
        return self.options


@dataclass(frozen=True, slots=True)
class SocketFrontEnd:
    """A registered protocol of the WebSocket listeners besides the default (rosbridge).

    Attributes:
        name: its name (``foxglove``), also its own listener's in ``GraphServer.urls``.
        make: its front end for one server and its options (made once, when the
            server is).
        options: where ``ServerConfig`` holds its options.
        on_port: whether ``ServerConfig`` puts it on the WebSocket port.
        own_port: the port of a listener that speaks only it; None: none.
    """

    name: str
    make: Callable[[FrontEndHost, object], FrontEnd]
    options: Callable[[ServerConfig], object]
    on_port: Callable[[ServerConfig], bool]
    own_port: Callable[[ServerConfig], int | None]


def webrtc_endpoint(host: FrontEndHost, options: object) -> HttpEndpoint:
    """WebRTC's endpoint (``webrtc.peers.webrtc_endpoint``): aiortc is loaded only now.

    Raises:
        ConfigError: ``options`` is not a ``WebRtcOptions``.
        ImportError: aiortc is not installed (``rwt-rosbridge[webrtc]``).
    """
    from .webrtc.peers import webrtc_endpoint as made  # noqa: PLC0415 (only with --webrtc)

    return made(host, options)


def mcp_endpoint(host: FrontEndHost, options: object) -> HttpEndpoint:
    """MCP's endpoint (``http.mcp.mcp_endpoint``): the MCP SDK is loaded only now.

    Raises:
        ConfigError: ``options`` is not an ``McpOptions``.
        ImportError: the MCP SDK is not installed (``rwt-rosbridge[mcp]``).
    """
    from .http.mcp import mcp_endpoint as made  # noqa: PLC0415 (only with --mcp)

    return made(host, options)


FOXGLOVE = SocketFrontEnd(
    "foxglove",
    foxglove_for,
    options=lambda config: config.foxglove,
    on_port=lambda config: config.foxglove.on_rosbridge_port,
    own_port=lambda config: config.foxglove.port,
)
"""The Foxglove WebSocket protocol (docs/foxglove.md): on the WebSocket port unless
``FoxgloveOptions.on_rosbridge_port`` is off, and on ``FoxgloveOptions.port`` if set."""

SOCKET_FRONTENDS: tuple[SocketFrontEnd, ...] = (FOXGLOVE,)
"""The protocols chosen by WebSocket subprotocol: Foxglove's (docs/foxglove.md)."""

VERSION = HttpFrontEnd(
    "version", (VERSION_PATH,), version_endpoint, options=True, auth=AuthMode.NONE
)
"""``GET /version`` (docs/server.md, D49): on unless ``ServerConfig.http_options["version"]``
is None."""

WEBRTC = HttpFrontEnd(
    "webrtc",
    (WEBRTC_PATH,),
    webrtc_endpoint,
    None,
    AuthMode.BEARER,
    transport="webrtc",
    configured=lambda config: config.webrtc,
)
"""WebRTC signalling (docs/webrtc.md): on with ``ServerConfig.webrtc`` (``rwt serve --webrtc``)."""

MCP = HttpFrontEnd(
    "mcp",
    (MCP_PATH, METADATA_PATH),
    mcp_endpoint,
    None,
    AuthMode.BEARER,
    configured=lambda config: config.mcp,
)
"""MCP over Streamable HTTP (docs/mcp.md): on with ``ServerConfig.mcp`` (``rwt serve --mcp``)."""

HTTP_API = HttpFrontEnd("http", API_PATHS, http_api_endpoint, HttpApiOptions(), AuthMode.BEARER)
"""The HTTP API (docs/http.md): on unless ``ServerConfig.http_options["http"]`` is None
(``rwt serve --no-http-api``); its options, ``rwt_http.HttpApiOptions``, there too."""

HTTP_FRONTENDS: tuple[HttpFrontEnd, ...] = (VERSION, WEBRTC, MCP, HTTP_API)
"""The HTTP front ends, in the order they are offered a request: ``GET /version``
(docs/server.md), WebRTC signalling (docs/webrtc.md; off unless ``ServerConfig.webrtc``),
MCP (docs/mcp.md; off unless ``ServerConfig.mcp``), the HTTP API (docs/http.md)."""
