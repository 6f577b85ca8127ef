"""A WebSocket client that reads only when the test says: a peer that stops reading."""

from __future__ import annotations

import anyio
from anyio.abc import SocketStream
from benchmarks.rawws import UPGRADE, masked_text, stalled_websocket

__all__ = ["masked_text", "raw_websocket", "stalled_websocket"]


async def raw_websocket(url: str, subprotocol: str) -> SocketStream:
    """Connect to ``url`` (``ws://127.0.0.1:PORT``) and send the upgrade for ``subprotocol``.

    Nothing is read: the test reads the response (and then as little as it wants).
    """
    port = int(url.rsplit(":", 1)[1].split("/", 1)[0])
    stream = await anyio.connect_tcp("127.0.0.1", port)
    await stream.send(UPGRADE.format(subprotocol=subprotocol).encode())
    return stream
