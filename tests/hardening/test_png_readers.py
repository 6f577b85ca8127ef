"""A ``png`` subscriber that reads gets every message; one that does not read is bounded.

Before, at most 4 messages of a topic could wait for deflating per connection
(``MAX_PNG_WAITING``): a burst lost all but those to a subscriber that read
everything (roslibjs got 4 of 12; tests/integration/test_clients_topics.py has
roslib's case). Now what waits for deflating counts with the outbox, by bytes
and time as D24 bounds every subscriber (docs/limits.md, png): it holds the
publisher back while the subscriber reads (input backpressure), and a
subscriber that does not read loses its oldest messages, stays within its send
buffer limit and is closed after ``--send-timeout``, while the reader and the
publisher go on.

A publisher sends ``COUNT`` 8 KB messages back to back (16 times the send
buffer limit, more than the kernel's buffers take for the non-reader); a png
subscriber reads them all, another never reads (a kernel receive buffer of 4
KB). Counts and bytes are asserted, not times.
"""

from __future__ import annotations

import base64
import json
import logging
import os
from collections.abc import AsyncIterator

import anyio
import anyio.to_thread
import pytest

from rwt_protocol.codecs.png import decode_png
from rwt_protocol.runtime.outbox import FRAME_OVERHEAD_BYTES
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.hardening.peers import TcpPeer, settle
from tests.support.clients import Harness, running_server

pytestmark = pytest.mark.anyio

LIMIT = 256 * 1024
COUNT = 500
PAYLOAD = 8 * 1024
TOPIC = "/png_burst"
MESSAGE_BYTES = PAYLOAD + 200  # a publish op's JSON text, as a waiting message is charged


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    session = SessionConfig(send_buffer_limit=LIMIT, send_timeout_s=1.0, hold_budget_s=10.0)
    async with running_server(ServerConfig(session=session)) as h:
        yield h


def subscribe_png(peer: TcpPeer, tag: str) -> None:
    peer.send({"op": "subscribe", "topic": TOPIC, "type": "std_msgs/String", "compression": "png"})
    settle(peer, tag)


def publish_burst(peer: TcpPeer) -> None:
    """``COUNT`` publishes, numbered, of text that does not compress, as one stream of bytes.

    Base64 of random bytes: its png op is larger than its JSON text, so the
    non-reader's kernel buffers fill with the fewest messages deflated.
    """
    peer.send({"op": "advertise", "topic": TOPIC, "type": "std_msgs/String"})
    ops = (
        {
            "op": "publish",
            "topic": TOPIC,
            "msg": {"data": f"{i:08d}{base64.b64encode(os.urandom(PAYLOAD * 3 // 4)).decode()}"},
        }
        for i in range(COUNT)
    )
    peer.send_raw(b"".join(json.dumps(op).encode() for op in ops))


def read_png_burst(peer: TcpPeer) -> list[int]:
    """The sequence numbers of the burst's ``png`` ops as received, until the last."""
    seen: list[int] = []
    while not seen or seen[-1] != COUNT - 1:
        frame = peer.receive()
        if frame.get("op") == "png":
            op = json.loads(decode_png(frame["data"], max_bytes=1 << 20))
            seen.append(int(op["msg"]["data"][:8]))
    return seen


async def test_a_png_reader_gets_every_message_and_a_non_reader_is_bounded_and_closed(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="rwt.server")
    port = harness.port("tcp")
    reader = await anyio.to_thread.run_sync(TcpPeer, port)
    stalled = await anyio.to_thread.run_sync(lambda: TcpPeer(port, rcvbuf=4096))
    publisher = await anyio.to_thread.run_sync(TcpPeer, port)
    await anyio.to_thread.run_sync(subscribe_png, reader, "r")
    await anyio.to_thread.run_sync(subscribe_png, stalled, "s")
    address = f"127.0.0.1:{stalled.sock.getsockname()[1]}"
    [session] = [s for s in harness.server.sessions.values() if s.peer == address]
    held: list[int] = []  # what the non-reader's connection holds, sampled
    result: list[list[int]] = []

    async def read() -> None:
        result.append(await anyio.to_thread.run_sync(read_png_burst, reader))

    async def sample() -> None:
        while not session.closing:
            held.append(session.stats.queued_bytes + session.stats.pending_bytes)
            await anyio.sleep(0.005)

    with anyio.fail_after(60):
        async with anyio.create_task_group() as tg:
            tg.start_soon(read)
            tg.start_soon(sample)
            await anyio.to_thread.run_sync(publish_burst, publisher)
        assert result[0] == list(range(COUNT))  # the reader: every message, in order
        # the non-reader: within its send buffer limit (and one message), then closed
        assert max(held) <= LIMIT + MESSAGE_BYTES + FRAME_OVERHEAD_BYTES
        assert session.stats.dropped_frames > 0
        while not [r for r in caplog.records if "slow consumer" in r.getMessage()]:
            await anyio.sleep(0.05)
    await anyio.to_thread.run_sync(settle, publisher, "after")  # the publisher goes on
    for peer in (reader, stalled, publisher):
        await anyio.to_thread.run_sync(peer.close)
