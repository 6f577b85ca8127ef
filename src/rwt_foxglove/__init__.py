"""The Foxglove WebSocket protocol on rwt's graph (docs/foxglove.md).

Foxglove and Lichtblick speak it (``foxglove.sdk.v1``, ``foxglove.websocket.v1``),
not rosbridge. ``protocol`` parses and encodes its ops, ``schemas`` describes the
graph's types as channels, ``wire`` reads and writes CDR payloads, ``session`` is
one client's protocol on the graph (a ``SessionBase``, as rosbridge's session is,
under the same per-client rules), with its parts ``services`` (service calls),
``params`` (parameters), ``conngraph`` (the connection graph), ``servertime`` (server
time while a bag plays), ``playback`` (the playback bar driving that bag) and
``assetrequests`` (asset requests), which send through ``output``; ``graphindex``
is what a client sees of the graph, kept from the graph's change feed; ``limits`` is the
Foxglove section of its bounds (all without I/O). ``assets`` finds and reads the
files clients fetch. The server's one connection runtime (``rwt_transports``) runs
the session; its front-end registry picks it by subprotocol in the handshake.
"""

from __future__ import annotations

from .assets import AssetRoots
from .limits import FoxgloveLimits
from .protocol import SUBPROTOCOLS, select_subprotocol
from .session import FoxgloveSession

__all__ = [
    "SUBPROTOCOLS",
    "AssetRoots",
    "FoxgloveLimits",
    "FoxgloveSession",
    "select_subprotocol",
]
