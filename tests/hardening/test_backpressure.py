"""Input backpressure: a burst reaches a subscriber that reads, whatever its size (docs/limits.md).

A publisher sends a burst of ``std_msgs/String`` publishes as fast as TCP
allows; the one subscriber reads as fast as it can. The send buffer is small
(1 MiB, several times less than the burst), so without backpressure on the
publisher's input the server queued the burst faster than the subscriber's
socket took it and dropped the oldest messages (D24). Now the publisher's
reader waits while the subscriber's outbox is over its high watermark, so every
message arrives, in order. A subscriber that does not read still has its
messages dropped and is closed, and the publisher and the other subscribers go on.
"""

from __future__ import annotations

import json
import logging
import socket
import time
from collections.abc import AsyncIterator

import anyio
import anyio.to_thread
import pytest

from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.hardening.peers import Peer, TcpPeer, open_peer, settle
from tests.support.clients import Harness, running_server

pytestmark = pytest.mark.anyio

MiB = 1024 * 1024
LIMIT = MiB // 4
BURST = 20_000  # about 8x the send buffer limit
TOPIC = "/burst"
SLOW_EVERY = 500


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    config = ServerConfig(session=SessionConfig(send_buffer_limit=LIMIT, send_timeout_s=1.0))
    async with running_server(config) as h:
        yield h


def ports(harness: Harness) -> dict[str, int]:
    return {kind: harness.port(kind) for kind in ("websocket", "tcp")}


def subscribe(peer: Peer, tag: str) -> None:
    peer.send({"op": "subscribe", "topic": TOPIC, "type": "std_msgs/String", "queue_length": 0})
    settle(peer, tag)


def publish_burst(peer: Peer, count: int, payload: int) -> None:
    """Send ``count`` publishes back to back; on TCP as one stream of bytes."""
    peer.send({"op": "advertise", "topic": TOPIC, "type": "std_msgs/String"})
    pad = "x" * payload
    ops = [
        {"op": "publish", "topic": TOPIC, "msg": {"data": f"{i:08d}{pad}"}} for i in range(count)
    ]
    if isinstance(peer, TcpPeer):
        peer.send_raw(b"".join(json.dumps(op).encode() for op in ops))
    else:
        for op in ops:
            peer.send(op)


def read_burst(peer: Peer, count: int, pause_s: float = 0.0) -> tuple[list[int], list[str]]:
    """The sequence numbers of the burst as received, and any status texts, until the last.

    With ``pause_s``, the reader sleeps that long after every ``SLOW_EVERY``
    messages: it reads on, slower than the burst comes.
    """
    seen: list[int] = []
    statuses: list[str] = []
    while not seen or seen[-1] != count - 1:
        if pause_s and len(seen) % SLOW_EVERY == SLOW_EVERY - 1:
            time.sleep(pause_s)
        message = peer.receive()
        if message.get("op") == "publish":
            seen.append(int(message["msg"]["data"][:8]))
        elif message.get("op") == "status":
            statuses.append(message["msg"])
    return seen, statuses


@pytest.mark.parametrize("pause_s", [0.0, 0.05], ids=["fast", "slow"])
@pytest.mark.parametrize("transport", ["ws", "tcp"])
async def test_burst_reaches_a_reading_subscriber_whole_and_in_order(
    harness: Harness, transport: str, pause_s: float
) -> None:
    """Fast: the subscriber reads as fast as it can. Slow: it pauses 50 ms every
    500 messages (at most 10,000 messages/s, slower than the server can take
    them), yet still reads: it must lose nothing either way."""
    addresses = ports(harness)
    subscriber = await anyio.to_thread.run_sync(open_peer, transport, addresses)
    publisher = await anyio.to_thread.run_sync(open_peer, transport, addresses)
    await anyio.to_thread.run_sync(subscribe, subscriber, "s")
    result: list[tuple[list[int], list[str]]] = []

    async def read() -> None:
        result.append(await anyio.to_thread.run_sync(read_burst, subscriber, BURST, pause_s))

    with anyio.fail_after(120):
        async with anyio.create_task_group() as tg:
            tg.start_soon(read)
            await anyio.to_thread.run_sync(publish_burst, publisher, BURST, 100)
    seen, statuses = result[0]
    assert seen == list(range(BURST))  # nothing dropped (D24's drops are for non-readers)
    assert not [s for s in statuses if "dropping" in s]
    # The server is up and serves the publisher's connection still.
    await anyio.to_thread.run_sync(settle, publisher, "after")
    for peer in (subscriber, publisher):  # off the loop: a WebSocket close awaits the server
        await anyio.to_thread.run_sync(peer.close)


def drain_until_closed(sock: socket.socket) -> int:
    """Read everything the server sends until it closes; the bytes read."""
    total = 0
    while True:
        try:
            chunk = sock.recv(1 << 16)
        except (ConnectionResetError, BrokenPipeError):
            return total
        if not chunk:
            return total
        total += len(chunk)


async def test_a_subscriber_that_does_not_read_is_dropped_and_closed_not_waited_for(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="rwt.server")
    addresses = ports(harness)
    reader = await anyio.to_thread.run_sync(open_peer, "tcp", addresses)
    stalled = await anyio.to_thread.run_sync(lambda: TcpPeer(addresses["tcp"], rcvbuf=4096))
    publisher = await anyio.to_thread.run_sync(open_peer, "tcp", addresses)
    await anyio.to_thread.run_sync(subscribe, reader, "r")
    await anyio.to_thread.run_sync(subscribe, stalled, "s")
    count = 8_000  # 1 KB each: 8 MB, eight times the stalled peer's send buffer limit
    result: list[tuple[list[int], list[str]]] = []

    async def read() -> None:
        result.append(await anyio.to_thread.run_sync(read_burst, reader, count))

    with anyio.fail_after(120):
        async with anyio.create_task_group() as tg:
            tg.start_soon(read)
            await anyio.to_thread.run_sync(publish_burst, publisher, count, 1000)
        # The publisher was not held up for good by the peer that reads nothing:
        # the reading subscriber has the whole burst, in order.
        assert result[0][0] == list(range(count))
        # The stalled one lost messages and was closed (send timeout 1 s, D24); it
        # reads only once the server says so, or reading would make it a reader.
        while not [r for r in caplog.records if "slow consumer" in r.getMessage()]:
            await anyio.sleep(0.05)
        received = await anyio.to_thread.run_sync(drain_until_closed, stalled.sock)
    assert received < count * 1000
    # The server is up: a new client is served.
    late = await anyio.to_thread.run_sync(open_peer, "ws", addresses)
    await anyio.to_thread.run_sync(settle, late, "late")
    for peer in (reader, stalled, publisher, late):  # off the loop, as above
        await anyio.to_thread.run_sync(peer.close)
