"""One host cannot take every connection slot (docs/limits.md, per server).

Before, one source address could open ``--max-connections`` connections (or
``--udp-max-sessions`` UDP sessions) and everyone else was refused. Now, once
3/4 of the slots are taken, a host holding its share gets no more, and its share
is never more than the slots still free, so the last free slot is for a host
holding none. Every test client is on loopback: 127.0.0.1 is the hog, 127.0.0.2
the other host (Linux routes all of 127/8 locally).

A host is a prefix of the source address (``--host-prefix-v4``, ``-v6``): three
addresses of one /24 took every slot while each counted alone; with
``--host-prefix-v4 24`` they share one host's slots.
"""

from __future__ import annotations

import json
import logging
import socket
from contextlib import AsyncExitStack

import anyio
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from rwt_transports.server import ServerConfig
from rwt_transports.udp.transport import UdpOptions
from tests.support.cli import invoke_rwt, port, rwt_serve
from tests.support.clients import Harness, running_server, validate_udp

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
    return await open_tcp(harness.stack, harness.port("tcp"), source)


async def open_tcp(stack: AsyncExitStack, port: int, source: str) -> bool:
    """Open a TCP connection from ``source``; whether the server admitted it (kept open)."""
    stream = await anyio.connect_tcp("127.0.0.1", port, local_host=source)
    stack.push_async_callback(anyio.aclose_forcefully, stream)
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


async def attempt(harness: Harness, transport: str, source: str) -> bool:
    """Whether a client from ``source`` gets a connection (or UDP session) on ``transport``."""
    if transport == "udp":
        return await open_udp(harness, source)
    return await open_stream(harness, transport, source)


@pytest.mark.parametrize("transport", ["ws", "tcp", "udp"])
async def test_one_host_cannot_take_every_slot(transport: str) -> None:
    # 8 slots, shares from 6 taken, 2 a host: the hog gets 6 (UDP) or 5 (the
    # harness's stdio session holds one); of the last 2 the other host gets one
    # (its share is the free slots: 2, then 1), a third host the last.
    config = ServerConfig(
        max_connections=8,
        max_connections_per_host=2,
        udp=UdpOptions(max_sessions=8, max_sessions_per_host=2),
    )
    if transport == "udp":
        config = ServerConfig(udp=UdpOptions(max_sessions=8, max_sessions_per_host=2))

    async with running_server(config) as harness:
        with anyio.fail_after(TIMEOUT_S):
            hog = 0
            while await attempt(harness, transport, "127.0.0.1"):
                hog += 1
            assert hog == (6 if transport == "udp" else 5)
            assert [await attempt(harness, transport, "127.0.0.2") for _ in range(2)] == [
                True,
                False,
            ]
            assert await attempt(harness, transport, "127.0.0.3")
            assert not await attempt(harness, transport, "127.0.0.4")  # the server is full


async def test_a_host_alone_is_not_limited_below_the_share_threshold() -> None:
    # Local use: every client is 127.0.0.1, far below 3/4 of the slots.
    config = ServerConfig(max_connections=100, max_connections_per_host=2)
    async with running_server(config) as harness:
        with anyio.fail_after(TIMEOUT_S):
            assert all([await open_stream(harness, "tcp", "127.0.0.1") for _ in range(20)])


HOG = ("127.0.0.1", "127.0.0.2", "127.0.0.3")  # one attacker's addresses, all in 127.0.0.0/24
OTHER = "127.0.1.1"  # another /24: another host even with --host-prefix-v4 24


@pytest.mark.parametrize("transport", ["ws", "tcp", "udp"])
@pytest.mark.parametrize(
    ("prefix_v4", "hog_gets", "other_gets"),
    [
        # 8 slots, shares from 6 taken, 4 a host (the stream servers' stdio session
        # holds one slot). Each address alone holds less than 4, but never more than
        # the free slots: the three stop short of the last slot, which the other host
        # gets; as one /24 they stop at 6 taken and the other host gets one of the
        # last two (its share shrinks to the free slots).
        (32, {"ws": 6, "tcp": 6, "udp": 6}, [True, False]),
        (24, {"ws": 5, "tcp": 5, "udp": 6}, [True, False]),
    ],
)
async def test_addresses_of_one_prefix_share_one_hosts_slots(
    transport: str, prefix_v4: int, hog_gets: dict[str, int], other_gets: list[bool]
) -> None:
    if transport == "udp":
        config = ServerConfig(
            host_prefix_v4=prefix_v4, udp=UdpOptions(max_sessions=8, max_sessions_per_host=4)
        )
    else:
        config = ServerConfig(
            max_connections=8, max_connections_per_host=4, host_prefix_v4=prefix_v4
        )

    async with running_server(config) as harness:
        with anyio.fail_after(TIMEOUT_S):
            hog = 0
            while await attempt(
                harness, transport, HOG[hog % len(HOG)]
            ):  # the three addresses in turn
                hog += 1
            assert hog == hog_gets[transport]
            assert [await attempt(harness, transport, OTHER) for _ in other_gets] == other_gets


async def test_rwt_serve_groups_ipv4_clients_by_host_prefix_v4() -> None:
    # The same over the command line: no stdio session, so the /24 stops at 6 of 8.
    args = ["--port", "0", "--tcp-port", "0", "--max-connections", "8"]
    args += ["--max-connections-per-host", "4", "--host-prefix-v4", "24"]
    async with rwt_serve(*args, listeners=2) as (_, urls), AsyncExitStack() as stack:
        with anyio.fail_after(TIMEOUT_S):
            tcp = port(urls["tcp"])
            hog = 0
            while await open_tcp(stack, tcp, HOG[hog % len(HOG)]):
                hog += 1
            assert hog == 6
            assert [await open_tcp(stack, tcp, OTHER) for _ in range(2)] == [True, False]


async def take_all(harness: Harness, transport: str, sources: list[str]) -> int:
    """Connect from ``sources`` in turn until one is refused; the connections admitted."""
    admitted = 0
    while await attempt(harness, transport, sources[admitted % len(sources)]):
        admitted += 1
    return admitted


@pytest.mark.parametrize("transport", ["ws", "tcp", "udp"])
@pytest.mark.parametrize("order", ["in turn", "one after another"])
async def test_three_addresses_leave_room_for_others_at_the_default_share(
    transport: str, order: str
) -> None:
    # --max-connections 40 with the default per-host share (64, 16 for UDP sessions):
    # each address alone held less than its share, so three took all 40 slots and
    # every other host was refused. Now a host's share is at most the free slots.
    if transport == "udp":
        config = ServerConfig(udp=UdpOptions(max_sessions=40))
        slots = 40
    else:
        config = ServerConfig(max_connections=40)
        slots = 39  # the harness's stdio session holds one
    async with running_server(config) as harness:
        with anyio.fail_after(TIMEOUT_S * 3):
            if order == "in turn":
                hog = await take_all(harness, transport, list(HOG))
            else:
                hog = sum([await take_all(harness, transport, [source]) for source in HOG])
            assert all([not await attempt(harness, transport, source) for source in HOG])
            others = [f"127.0.1.{index}" for index in range(1, 41)]
            served = 0
            for source in others:  # other hosts, one connection each, until the server is full
                if not await attempt(harness, transport, source):
                    break
                served += 1
    assert hog < slots - 1  # the three left room...
    assert served == slots - hog  # ...and other hosts got every slot they left


def ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6) as sock:
            sock.bind(("::1", 0))
    except OSError:
        return False
    return True


@pytest.mark.skipif(not ipv6_loopback(), reason="no IPv6 loopback")
@pytest.mark.parametrize(("prefix_v6", "host"), [(64, "::/64"), (128, "::1")])
async def test_an_ipv6_client_counts_by_its_prefix(
    prefix_v6: int, host: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="rwt.server")
    config = ServerConfig(
        host="::1", max_connections=8, max_connections_per_host=2, host_prefix_v6=prefix_v6
    )
    async with running_server(config) as harness:
        with anyio.fail_after(TIMEOUT_S):
            admitted = 0
            while True:
                stream = await anyio.connect_tcp("::1", harness.port("tcp"))
                harness.stack.push_async_callback(anyio.aclose_forcefully, stream)
                await stream.send(SET_LEVEL)
                reply = json.loads((await stream.receive()).split(b"\n")[0])
                if reply.get("msg") == "too many connections":
                    break
                admitted += 1
    assert admitted == 5  # shares from 6 of 8 taken (the stdio session holds one)
    refusals = [r.getMessage() for r in caplog.records if "host share" in r.getMessage()]
    assert refusals and all(f" host={host} " in line for line in refusals), refusals


@pytest.mark.parametrize(
    ("option", "value", "problem"),
    [
        ("--host-prefix-v4", "33", "input should be less than or equal to 32"),
        ("--host-prefix-v4", "-1", "input should be greater than or equal to 0"),
        ("--host-prefix-v6", "129", "input should be less than or equal to 128"),
        ("--host-prefix-v6", "-1", "input should be greater than or equal to 0"),
    ],
)
def test_a_prefix_longer_than_the_address_is_refused_by_the_cli(
    option: str, value: str, problem: str
) -> None:
    result = invoke_rwt("serve", option, value)
    assert result.exit_code == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.strip() == f"rwt serve: {option}: {problem}"
