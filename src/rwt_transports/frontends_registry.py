"""The one registry of the server's front ends: every protocol and way in it serves.

A front end is found here by what selects it (``frontends``):

- a WebSocket subprotocol in the handshake (``SOCKET_FRONTENDS``: Foxglove's); a
  client that offers none gets the default, rosbridge (``rosbridge_frontend``);
- a WebRTC data channel's label: rosbridge's ``rosbridge`` (``DATA_CHANNEL_LABEL``)
  and its lossy ``rosbridge-lossy`` (``LOSSY_CHANNEL_LABEL``, D36), or a
  registered protocol's (``FrontEnd.labels``); any other label is refused;
- an HTTP path on the WebSocket port (``HTTP_FRONTENDS``): ``/version``, WebRTC's
  signalling, MCP, the HTTP API.

The server makes each from here (``GraphServer``) and knows none by name;
``ServerConfig.http_options`` gives an HTTP front end its options, or None to turn
it off. Adding a front end is its own package, its transport module and a line here
(docs/architecture.md, "How to add").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .foxglove import FOXGLOVE
from .frontends import AuthMode, FrontEnd
from .http_api import HTTP_API
from .mcp_options import MCP
from .version_http import VERSION
from .webrtc_signal import WEBRTC

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.runtime.contract import ServerSession

    from .frontends import HttpFrontEnd, SessionRequest, SocketFrontEnd

__all__ = [
    "DATA_CHANNEL_LABEL",
    "HTTP_FRONTENDS",
    "LOSSY_CHANNEL_LABEL",
    "SOCKET_FRONTENDS",
    "rosbridge_frontend",
]

DATA_CHANNEL_LABEL = "rosbridge"
"""The label of the reliable, ordered data channel that carries a rosbridge session."""

LOSSY_CHANNEL_LABEL = "rosbridge-lossy"
"""The label of a rosbridge session's lossy channel (``ordered: false, maxRetransmits`` 0 or
1; D36, D73)."""

SOCKET_FRONTENDS: tuple[SocketFrontEnd, ...] = (FOXGLOVE,)
"""The protocols chosen by WebSocket subprotocol: Foxglove's (docs/foxglove.md)."""

HTTP_FRONTENDS: tuple[HttpFrontEnd, ...] = (VERSION, WEBRTC, MCP, HTTP_API)
"""The HTTP front ends, in the order they are offered a request: ``GET /version``
(docs/server.md), WebRTC signalling (docs/webrtc.md; off unless ``ServerConfig.webrtc``),
MCP (docs/mcp.md; off unless ``ServerConfig.mcp``), the HTTP API (docs/http.md)."""


def rosbridge_frontend(make_session: Callable[[SessionRequest], ServerSession]) -> FrontEnd:
    """rosbridge, the default front end: no subprotocol, its data-channel labels, the auth op."""
    return FrontEnd(
        "rosbridge",
        (),
        make_session,
        AuthMode.OP,
        labels=(DATA_CHANNEL_LABEL,),
        lossy_labels=(LOSSY_CHANNEL_LABEL,),
    )
