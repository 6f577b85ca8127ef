"""WebSocket clients that do what a test says: a peer that stops reading, one that sends
its upgrade and first messages in one write.
"""

from __future__ import annotations

import asyncio
import json
import socket
from dataclasses import dataclass

import anyio
from anyio.abc import SocketStream
from benchmarks.rawws import UPGRADE, masked_text, stalled_websocket
from websockets.client import ClientProtocol
from websockets.frames import Frame, Opcode
from websockets.uri import parse_uri

__all__ = [
    "NeverReading",
    "masked_text",
    "raw_websocket",
    "server_frame",
    "stalled_websocket",
    "upgrade_with",
]


@dataclass
class NeverReading:
    """A WebSocket client on a plain socket: it reads the handshake's answer, then nothing.

    It sends what the test says (``send``) and never reads or answers a ping, so the
    server's frames stay in its socket buffers and then in the server's outbox.
    """

    sock: socket.socket
    protocol: ClientProtocol

    @classmethod
    async def connect(cls, port: int, receive_buffer: int | None = 4096) -> NeverReading:
        """Connect to ``ws://127.0.0.1:port/`` and complete the handshake.

        ``receive_buffer``: the socket's ``SO_RCVBUF`` in bytes, small so that the
        kernel holds little of what the server sends; None: the system's.
        """
        loop = asyncio.get_running_loop()
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if receive_buffer is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
        sock.setblocking(False)
        await loop.sock_connect(sock, ("127.0.0.1", port))
        protocol = ClientProtocol(parse_uri(f"ws://127.0.0.1:{port}/"))
        protocol.send_request(protocol.connect())
        client = cls(sock, protocol)
        await client._flush()
        while protocol.handshake_exc is None and not protocol.events_received():
            protocol.receive_data(await loop.sock_recv(sock, 4096))
        return client

    async def send(self, op: dict[str, object]) -> None:
        """Send ``op`` as a text frame (OSError once the server ended the connection)."""
        self.protocol.send_frame(Frame(Opcode.TEXT, json.dumps(op).encode()))
        await self._flush()

    async def _flush(self) -> None:
        for data in self.protocol.data_to_send():
            await asyncio.get_running_loop().sock_sendall(self.sock, data)

    def close(self) -> None:
        """Close the socket (no closing handshake)."""
        self.sock.close()


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
