"""One host cannot take every connection slot (docs/limits.md, per server).

Before, one source address could open ``--max-connections`` connections (or
``--udp-max-sessions`` UDP sessions) and everyone else was refused. Now, once
3/4 of the slots are taken, a host holding its share gets no more, and the
remaining slots go to hosts that hold less. Every test client is on loopback:
127.0.0.1 is the hog, 127.0.0.2 the other host (Linux routes all of 127/8 locally).
"""

from __future__ import annotations

import json

import anyio
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from rwt_transports.server import ServerConfig
from rwt_transports.udp import UdpOptions
from tests.transports.clients import Harness, running_server, validate_udp

pytestmark = pytest.mark.anyio

TIMEOUT_S = 10
SET_LEVEL = b'{"op":"set_level","level":"info","id":"in"}'


async def open_stream(harness: Harness, transport: str, source: str) -> bool:
    """Open a connection from ``source``; whether the server admitted it (kept open)."""
    if transport == "ws":
        try:
            ws = await connect(
                f"ws://127.0.0.1:{harness.port('websocket')}", local_addr=(source, 0)
            )
        except InvalidStatus as refused:
            assert refused.response.status_code == 503
            return False
        harness.stack.push_async_callback(ws.close)
        await ws.send(SET_LEVEL.decode())
        return bool(json.loads(await ws.recv())["id"] == "in")
    stream = await anyio.connect_tcp("127.0.0.1", harness.port("tcp"), local_host=source)
    harness.stack.push_async_callback(anyio.aclose_forcefully, stream)
    await stream.send(SET_LEVEL)
    reply = json.loads((await stream.receive()).split(b"\n")[0])
    if reply.get("msg") == "too many connections":
        return False
    return bool(reply["id"] == "in")


async def open_udp(harness: Harness, source: str) -> bool:
    sock = await anyio.create_connected_udp_socket(
        "127.0.0.1", harness.port("udp"), local_host=source
    )
    harness.stack.push_async_callback(sock.aclose)
    prefix = await validate_udp(sock)
    await sock.send(prefix + SET_LEVEL)
    reply = json.loads(await sock.receive())
    if reply.get("msg") == "too many connections":
        return False
    return bool(reply["id"] == "in")


@pytest.mark.parametrize("transport", ["ws", "tcp", "udp"])
async def test_one_host_cannot_take_every_slot(transport: str) -> None:
    # 8 slots, shares from 6 taken, 2 a host: the hog gets 6 (UDP) or 5 (the
    # harness's stdio session holds one), the other host the last 2.
    config = ServerConfig(
        max_connections=8,
        max_connections_per_host=2,
        udp=UdpOptions(max_sessions=8, max_sessions_per_host=2),
    )
    if transport == "udp":
        config = ServerConfig(udp=UdpOptions(max_sessions=8, max_sessions_per_host=2))

    async def attempt(source: str) -> bool:
        if transport == "udp":
            return await open_udp(harness, source)
        return await open_stream(harness, transport, source)

    async with running_server(config) as harness:
        with anyio.fail_after(TIMEOUT_S):
            hog = 0
            while await attempt("127.0.0.1"):
                hog += 1
            assert hog == (6 if transport == "udp" else 5)
            assert [await attempt("127.0.0.2") for _ in range(3)] == [True, True, False]


async def test_a_host_alone_is_not_limited_below_the_share_threshold() -> None:
    # Local use: every client is 127.0.0.1, far below 3/4 of the slots.
    config = ServerConfig(max_connections=100, max_connections_per_host=2)
    async with running_server(config) as harness:
        with anyio.fail_after(TIMEOUT_S):
            assert all([await open_stream(harness, "tcp", "127.0.0.1") for _ in range(20)])
