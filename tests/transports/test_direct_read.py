"""Reading a plain socket without pausing it after each chunk keeps input bounded (issue 8).

``DirectReader`` leaves a connection readable while its reader waits, and the
WebSocket channel pauses it before the one other await of its reader: the
flush of answers to control frames. A peer that sends pings and never reads
the pongs must therefore be stopped by TCP's flow control, not buffered in the
server, and the server must go on serving everyone else.
"""

from __future__ import annotations

import base64
import os
import socket
import struct

import anyio
import anyio.to_thread
import pytest

from rwt_transports.server import ServerConfig
from tests.transports.clients import running_server

pytestmark = pytest.mark.anyio

MiB = 1024 * 1024
LIMIT = 256 * MiB  # far beyond the kernel buffers of both ends (32 + 4 MiB here)


@pytest.fixture(
    params=[
        pytest.param({}, id="asyncio"),
        pytest.param(
            {"use_uvloop": True},
            id="uvloop",
            # Open bug (issue 8, fifth session): on a loaded machine, 1 run in a few
            # dozen took all 256 MiB on uvloop (once in a full CI run). Not yet
            # known whether the server buffered the pongs or stopped answering.
            marks=pytest.mark.xfail(strict=False, reason="intermittent on uvloop under load"),
        ),
    ]
)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, bool]]:
    return "asyncio", request.param


def _ping() -> bytes:
    key = os.urandom(4)
    payload = b"p" * 125
    masked = bytes(b ^ key[i % 4] for i, b in enumerate(payload))
    return struct.pack("!BB", 0x89, 0x80 | 125) + key + masked


def _flood(port: int) -> int:
    """Open a WebSocket, then send pings without reading; return the bytes sent before blocking."""
    sock = socket.create_connection(("127.0.0.1", port))
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 65536)  # pongs back up soon
        key = base64.b64encode(os.urandom(16)).decode()
        sock.sendall(
            (
                "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        response = b""
        while b"\r\n\r\n" not in response:
            response += sock.recv(4096)
        assert response.startswith(b"HTTP/1.1 101")
        burst = _ping() * 512
        sent = 0
        sock.settimeout(1.0)  # blocked this long: the server stopped reading
        while sent < LIMIT:
            try:
                sent += sock.send(burst)
            except TimeoutError:
                break
        return sent
    finally:
        sock.close()


async def test_a_peer_that_pings_without_reading_is_held_back_by_tcp() -> None:
    async with running_server(ServerConfig()) as harness:
        with anyio.fail_after(60):
            sent = await anyio.to_thread.run_sync(_flood, harness.port("websocket"))
            assert sent < LIMIT // 2, f"the server took {sent / MiB:.0f} MiB it could not answer"
            other = await harness.connect("ws")
            await other.send({"op": "call_service", "service": "/rosapi/topics", "id": "after"})
            reply = await other.expect(lambda m: m.get("id") == "after")
    assert reply["result"] is True
