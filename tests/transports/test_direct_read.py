"""Reading a plain socket without pausing it after each chunk keeps input bounded.

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
import threading

import anyio
import anyio.to_thread
import pytest
from anyio.abc import SocketAttribute

from rwt_protocol.shortcuts import ENV_VAR
from rwt_transports.direct import DirectReader
from rwt_transports.server import ServerConfig
from tests.support.clients import running_server

pytestmark = [pytest.mark.anyio, pytest.mark.uvloop_too]  # the paths differ under uvloop

MiB = 1024 * 1024
LIMIT = 256 * MiB  # far beyond the kernel buffers of both ends (32 + 4 MiB here)


def _ping() -> bytes:
    key = os.urandom(4)
    payload = b"p" * 125
    masked = bytes(b ^ key[i % 4] for i, b in enumerate(payload))
    return struct.pack("!BB", 0x89, 0x80 | 125) + key + masked


def _send_until_blocked(sock: socket.socket, burst: bytes) -> int:
    """Send ``burst`` over and over until a send blocks for 1 s (the peer stopped
    reading) or ``LIMIT`` bytes went; return the bytes sent."""
    sent = 0
    sock.settimeout(1.0)
    while sent < LIMIT:
        try:
            sent += sock.send(burst)
        except TimeoutError:
            break
    return sent


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
        return _send_until_blocked(sock, _ping() * 512)
    finally:
        sock.close()


async def test_a_peer_that_pings_without_reading_is_held_back_by_tcp(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The direct reader's guarantee, whatever the switch: the general path reads with
    anyio's ``receive``, which leaves a new connection reading until a read has to wait
    (docs/shortcuts.md), so it does not hold such a peer back on every event loop."""
    monkeypatch.delenv(ENV_VAR, raising=False)  # the direct reader itself
    async with running_server(ServerConfig()) as harness:
        with anyio.fail_after(60):
            sent = await anyio.to_thread.run_sync(_flood, harness.port("websocket"))
            assert sent < LIMIT // 2, f"the server took {sent / MiB:.0f} MiB it could not answer"
            other = await harness.connect("ws")
            await other.send({"op": "call_service", "service": "/rosapi/topics", "id": "after"})
            reply = await other.expect(lambda m: m.get("id") == "after")
    assert reply["result"] is True


def _hello_then_flood(port: int, go: threading.Event) -> int:
    """Connect and send ``hello``; once ``go`` is set, send until a send blocks for 1 s."""
    sock = socket.create_connection(("127.0.0.1", port))
    try:
        sock.sendall(b"hello")
        if not go.wait(30):
            return -1
        return _send_until_blocked(sock, b"x" * 65536)
    finally:
        sock.close()


async def test_pause_holds_the_peer_back_after_an_early_first_read(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """anyio's ``receive`` leaves reading on when the bytes were queued before it was
    called (a handshake that arrived at once); ``pause`` must still stop reading."""
    monkeypatch.delenv(ENV_VAR, raising=False)  # the direct reader itself, whatever the switch
    go = threading.Event()
    async with await anyio.create_tcp_listener(local_host="127.0.0.1") as listener:
        port = listener.extra(SocketAttribute.local_port)
        async with anyio.create_task_group() as tg:
            result: list[int] = []

            async def peer() -> None:
                result.append(await anyio.to_thread.run_sync(_hello_then_flood, port, go))

            tg.start_soon(peer)
            server = await listener.listeners[0].accept()
            async with server:
                await anyio.sleep(0.5)  # "hello" is queued before the first read
                assert (await server.receive()) == b"hello"
                reader = DirectReader.for_stream(server)
                assert reader is not None
                reader.pause()
                go.set()
                with anyio.fail_after(60):
                    while not result:
                        await anyio.sleep(0.1)
    assert 0 <= result[0] < LIMIT // 2, f"the paused reader took {result[0] / MiB:.0f} MiB"
