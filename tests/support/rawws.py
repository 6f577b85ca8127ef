"""WebSocket clients that do what a test says: a peer that stops reading, one that sends
its upgrade and first messages in one write.
"""

from __future__ import annotations

import json

import anyio
from anyio.abc import SocketStream
from benchmarks.rawws import UPGRADE, masked_text, stalled_websocket
from websockets.frames import Frame, Opcode

__all__ = ["masked_text", "raw_websocket", "server_frame", "stalled_websocket", "upgrade_with"]


async def raw_websocket(url: str, subprotocol: str) -> SocketStream:
    """Connect to ``url`` (``ws://127.0.0.1:PORT``) and send the upgrade for ``subprotocol``.

    Nothing is read: the test reads the response (and then as little as it wants).
    """
    port = int(url.rsplit(":", 1)[1].split("/", 1)[0])
    stream = await anyio.connect_tcp("127.0.0.1", port)
    await stream.send(UPGRADE.format(subprotocol=subprotocol).encode())
    return stream


def upgrade_with(port: int, messages: list[object]) -> bytes:
    """An upgrade request to ``127.0.0.1:port`` and ``messages`` as masked text frames:
    what a client that sends everything at once writes.
    """
    request = (
        f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
        "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
        "Sec-WebSocket-Version: 13\r\n\r\n"
    ).encode()
    frames = (Frame(Opcode.TEXT, json.dumps(m).encode()).serialize(mask=True) for m in messages)
    return request + b"".join(frames)


def server_frame(data: bytes) -> tuple[int, bytes, bytes] | None:
    """The first (unmasked) server frame in ``data``: its opcode, payload and the bytes after
    it; None while it is not whole.
    """
    if len(data) < 2:
        return None
    size, start = data[1] & 0x7F, 2
    if size >= 126:
        start = 4 if size == 126 else 10
        if len(data) < start:
            return None
        size = int.from_bytes(data[2:start], "big")
    if len(data) < start + size:
        return None
    return data[0] & 0x0F, data[start : start + size], data[start + size :]
