"""A WebSocket client that reads only when the test says: a peer that stops reading."""

from __future__ import annotations

import socket
import struct

import anyio
from anyio.abc import SocketStream

__all__ = ["masked_text", "raw_websocket", "stalled_websocket"]

_UPGRADE = (
    "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
    "Sec-WebSocket-Protocol: {subprotocol}\r\n\r\n"
)


async def raw_websocket(url: str, subprotocol: str) -> SocketStream:
    """Connect to ``url`` (``ws://127.0.0.1:PORT``) and send the upgrade for ``subprotocol``.

    Nothing is read: the test reads the response (and then as little as it wants).
    """
    port = int(url.rsplit(":", 1)[1].split("/", 1)[0])
    stream = await anyio.connect_tcp("127.0.0.1", port)
    await stream.send(_UPGRADE.format(subprotocol=subprotocol).encode())
    return stream


def stalled_websocket(
    port: int, subprotocol: str, until: bytes, rcvbuf: int = 4096
) -> socket.socket:
    """A blocking WebSocket to 127.0.0.1:``port`` that reads until ``until`` came, then stops.

    Its kernel receive buffer is ``rcvbuf`` bytes, so the kernel takes little for
    it: what the server sends it afterwards waits in the server (a peer that does
    not read). The caller sends with ``masked_text`` and closes the socket.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    sock.settimeout(30)
    sock.connect(("127.0.0.1", port))
    sock.sendall(_UPGRADE.format(subprotocol=subprotocol).encode())
    received = b""
    while until not in received:
        chunk = sock.recv(4096)
        if not chunk:
            raise EOFError("the server closed the connection")
        received += chunk
    return sock


def masked_text(payload: bytes) -> bytes:
    """One client text frame of ``payload`` (masked with an all-zero mask, RFC 6455 5.3)."""
    if len(payload) < 126:
        return bytes((0x81, 0x80 | len(payload))) + bytes(4) + payload
    return bytes((0x81, 0xFE)) + struct.pack("!H", len(payload)) + bytes(4) + payload
