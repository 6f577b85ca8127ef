"""Raw-socket WebSocket client pieces: handshake, pre-built frames, frame parsing.

The load generator must be lighter than the servers it measures
(docs/benchmarks.md), so it does not run a WebSocket library per message: client
frames are built once before a run (masked with the all-zero key, which RFC 6455
allows and which leaves the payload as it is) and written in batches; incoming
bytes are either compared with the expected byte stream at C speed
(``ExactStream``) or cut into frames by a small parser (``FrameReader``).
"""

from __future__ import annotations

import base64
import os
import socket
import struct

__all__ = [
    "OP_BINARY",
    "OP_TEXT",
    "FrameReader",
    "as_served",
    "client_frame",
    "connect",
    "server_frame",
]

OP_TEXT = 0x1
OP_BINARY = 0x2
_ZERO_MASK = b"\0\0\0\0"


def _header(payload_len: int, first: int, mask_bit: int) -> bytes:
    if payload_len < 126:
        return bytes((first, mask_bit | payload_len))
    if payload_len < 65536:
        return struct.pack("!BBH", first, mask_bit | 126, payload_len)
    return struct.pack("!BBQ", first, mask_bit | 127, payload_len)


def client_frame(payload: bytes, *, binary: bool = False) -> bytes:
    """One complete client-to-server frame (FIN, masked with the zero key)."""
    first = 0x80 | (OP_BINARY if binary else OP_TEXT)
    return _header(len(payload), first, 0x80) + _ZERO_MASK + payload


def as_served(kind: str, payload: bytes) -> bytes:
    """The JSON text a server of ``kind`` writes for the compact ``payload`` rwt writes.

    rosbridge_suite 0.11 (ROS 1) serializes with ujson, which escapes every
    ``/`` as ``\\/``; rwt and the bare relay write the payload as it is.
    """
    return payload.replace(b"/", b"\\/") if kind == "rosbridge" else payload


def server_frame(payload: bytes, *, binary: bool = False) -> bytes:
    """The frame a server sends for ``payload`` (FIN, unmasked, no extension)."""
    first = 0x80 | (OP_BINARY if binary else OP_TEXT)
    return _header(len(payload), first, 0) + payload


def connect(
    port: int, path: str = "/", host: str = "127.0.0.1", *, rcvbuf: int | None = None
) -> tuple[socket.socket, bytes]:
    """Open a WebSocket connection (blocking handshake, 10 s limit).

    Args:
        port: the server's port.
        path: the request path (the bare relay's ``/sub`` for receivers).
        host: the server's address.
        rcvbuf: a receive buffer size in bytes (a stalled client), else the default.

    Returns:
        The socket (still blocking) and the bytes received after the handshake
        response (the start of the frame stream).

    Raises:
        ConnectionError: the server did not answer ``101``.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    if rcvbuf is not None:  # before connect, so the window is small from the start
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    sock.settimeout(10.0)
    sock.connect((host, port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    key = base64.b64encode(os.urandom(16)).decode()
    request = (
        f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    sock.sendall(request.encode())
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError("connection closed during the handshake")
        data += chunk
    head, _, rest = data.partition(b"\r\n\r\n")
    if not head.startswith(b"HTTP/1.1 101"):
        raise ConnectionError(f"handshake refused: {head[:80]!r}")
    return sock, rest


class FrameReader:
    """Cuts a server's byte stream into ``(opcode, payload)`` frames.

    Continuation frames are not reassembled (neither server fragments its
    frames); a control frame (ping, close) is returned like any other.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._need = 2

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        """Add received bytes; return the frames they complete, in order."""
        buf = self._buf
        buf += data
        if len(buf) < self._need:
            return []
        frames: list[tuple[int, bytes]] = []
        pos = 0
        end = len(buf)
        self._need = 2
        while end - pos >= 2:
            opcode = buf[pos] & 0x0F
            length = buf[pos + 1] & 0x7F
            start = pos + 2
            if length == 126:
                if end - pos < 4:
                    self._need = 4
                    break
                length = (buf[pos + 2] << 8) | buf[pos + 3]
                start = pos + 4
            elif length == 127:
                if end - pos < 10:
                    self._need = 10
                    break
                (length,) = struct.unpack_from("!Q", buf, pos + 2)
                start = pos + 10
            stop = start + length
            if stop > end:
                self._need = stop - pos
                break
            frames.append((opcode, bytes(buf[start:stop])))
            pos = stop
        if pos:
            del buf[:pos]
        return frames

    def take_rest(self) -> bytes:
        """Remove and return the bytes of the incomplete frame held so far."""
        rest = bytes(self._buf)
        self._buf.clear()
        self._need = 2
        return rest
