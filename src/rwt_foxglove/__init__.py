"""The Foxglove WebSocket protocol on rwt's graph (docs/foxglove.md).

Foxglove and Lichtblick speak it (``foxglove.sdk.v1``, ``foxglove.websocket.v1``),
not rosbridge. ``protocol`` parses and encodes its ops, ``schemas`` describes the
graph's types as channels, ``wire`` reads and writes CDR payloads, ``session`` is
one client's protocol on the graph, with its parts ``services`` (service calls),
``params`` (parameters), ``conngraph`` (the connection graph), ``servertime`` (server
time while a bag plays), ``playback`` (the playback bar driving that bag) and
``assetrequests`` (asset requests), which send through
``output``; ``outqueue`` is its bounded queue and ``limits`` its bounds (all without
I/O). ``assets`` finds and reads the files clients fetch, ``driver`` runs a session
over a WebSocket connection, ``gather`` gathering a burst's frames into few writes;
``rwt_transports`` picks it in the handshake.
"""

from __future__ import annotations

from .assets import AssetRoots
from .driver import FoxgloveChannel, Wakeup, run_foxglove
from .limits import FoxgloveLimits
from .protocol import SUBPROTOCOLS, select_subprotocol
from .session import FoxgloveSession

__all__ = [
    "SUBPROTOCOLS",
    "AssetRoots",
    "FoxgloveChannel",
    "FoxgloveLimits",
    "FoxgloveSession",
    "Wakeup",
    "run_foxglove",
    "select_subprotocol",
]
