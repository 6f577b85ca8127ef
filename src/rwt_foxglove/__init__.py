"""The Foxglove WebSocket protocol on rwt's graph (docs/foxglove.md).

Foxglove and Lichtblick speak it (``foxglove.sdk.v1``, ``foxglove.websocket.v1``),
not rosbridge. ``protocol`` parses and encodes its ops, ``schemas`` describes the
graph's types as channels, ``session`` is one client's protocol on the graph,
``servertime`` and ``assetrequests`` its server time and asset requests (all
without I/O); ``assets`` finds and reads the files clients fetch, and
``driver`` runs a session over a WebSocket connection; ``rwt_transports``
picks it in the handshake.
"""

from __future__ import annotations

from .assets import AssetRoots
from .driver import FoxgloveChannel, Wakeup, run_foxglove
from .protocol import SUBPROTOCOLS, select_subprotocol
from .session import FoxgloveLimits, FoxgloveSession

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
