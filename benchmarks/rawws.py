"""Raw WebSocket clients that read only when told: peers that stop reading.

Shared by the attack replays and the suite's hardening tests (tests/support/rawws.py).
"""

from __future__ import annotations

import socket
import struct

__all__ = ["UPGRADE", "masked_text", "stalled_websocket"]

UPGRADE = (
    "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
    "Sec-WebSocket-Protocol: {subprotocol}\r\n\r\n"
)
"""A client's upgrade request for ``{subprotocol}`` (a fixed key: the tests read no accept)."""

TIMEOUT_S = 30.0  # a bound on a hung server, not a speed requirement


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
    sock.settimeout(TIMEOUT_S)
    sock.connect(("127.0.0.1", port))
    sock.sendall(UPGRADE.format(subprotocol=subprotocol).encode())
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
