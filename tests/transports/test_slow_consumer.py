"""A subscriber that never reads cannot hurt the others nor grow server memory (D24, REF §9.1).

Nine WebSocket subscribers read everything; a tenth completes the handshake,
subscribes and then never reads, with a tiny receive buffer. The nine get every
message; the server's traced memory stays under baseline + the send buffer
limit (plus slack) although far more than that is published; the stalled
connection's drops are counted and it is closed after ``send_timeout_s``.
"""

from __future__ import annotations

import json
import logging
import tracemalloc
from collections.abc import AsyncIterator

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect

from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.support.clients import Harness, running_server
from tests.support.rawws import NeverReading

pytestmark = pytest.mark.anyio

MiB = 1024 * 1024
LIMIT = 1 * MiB
MESSAGES = 1200
PAYLOAD = 10_000  # bytes per message: 12 MB published in all, twelve times the limit
BATCH = 100


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    config = ServerConfig(session=SessionConfig(send_buffer_limit=LIMIT, send_timeout_s=1.0))
    async with running_server(config) as h:
        yield h


async def reader(ws: ClientConnection, counts: list[int], index: int) -> None:
    async for text in ws:
        if json.loads(text)["op"] == "publish":
            counts[index] += 1


async def test_nine_readers_get_everything_while_a_stalled_one_is_cut(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, "rwt")
    port = harness.port("websocket")
    server = harness.server
    readers = []
    for _ in range(9):
        ws = await connect(f"ws://127.0.0.1:{port}", max_size=None)
        await ws.send(json.dumps({"op": "subscribe", "topic": "/flood", "type": "std_msgs/String"}))
        readers.append(ws)
    stalled = await NeverReading.connect(port)  # subscribes, then never reads again
    await stalled.send({"op": "subscribe", "topic": "/flood", "type": "std_msgs/String"})
    publisher = server.graph.create_publisher("/flood", "std_msgs/msg/String")
    counts = [0] * 9
    try:
        async with anyio.create_task_group() as tg:
            for i, ws in enumerate(readers):
                tg.start_soon(reader, ws, counts, i)
            with anyio.fail_after(30):
                while len([s for s in server.sessions.values() if s.holdings.subscriptions]) < 10:
                    await anyio.sleep(0.01)  # every subscription has been processed
                slow = list(server.sessions.values())[-1]  # the stalled one connected last
                tracemalloc.start()
                baseline = tracemalloc.get_traced_memory()[0]
                grown = 0
                for sent in range(BATCH, MESSAGES + 1, BATCH):
                    for i in range(BATCH):
                        publisher.publish({"data": f"{sent + i:08d}" + "x" * PAYLOAD})
                    while min(counts) < sent:  # paced by the readers, not by the stalled one
                        await anyio.sleep(0.005)
                    grown = max(grown, tracemalloc.get_traced_memory()[0] - baseline)
                tracemalloc.stop()
                while slow.client_id in server.sessions:  # cut after send_timeout_s
                    await anyio.sleep(0.05)
            tg.cancel_scope.cancel()
    finally:
        stalled.close()
        for ws in readers:
            await ws.close()
    assert counts == [MESSAGES] * 9
    assert grown < LIMIT + 2 * MiB, f"server memory grew by {grown} bytes"
    assert slow.stats.dropped_frames > 0
    closing = [r.getMessage() for r in caplog.records if "event=closing" in r.getMessage()]
    assert any(
        slow.client_id in line and "slow consumer: send buffer over 1048576 bytes for 1 s" in line
        for line in closing
    ), closing
    disconnect = [r.getMessage() for r in caplog.records if "event=disconnect" in r.getMessage()]
    assert any(
        slow.client_id in line and f"dropped={slow.stats.dropped_frames}" in line
        for line in disconnect
    )
