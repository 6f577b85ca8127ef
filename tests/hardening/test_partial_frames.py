"""Frames still arriving draw from the server-wide budget of incomplete messages.

A TCP value without its end, a WebSocket frame begun or the first frames of a
fragmented WebSocket message are kept until whole, up to ``--max-message-size``
per connection. Before, nothing bounded them over all connections: 120
connections that each sent 10 MB of one frame held 1.2 GB. They now count against
``--max-fragment-memory`` as incomplete ``fragment`` ops do (docs/limits.md).
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
from collections.abc import AsyncIterator

import anyio
import pytest
from anyio.abc import SocketStream
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from rwt_transports.server import ServerConfig
from tests.support.clients import Harness, StreamClient, is_op, running_server

pytestmark = pytest.mark.anyio

TIMEOUT_S = 30
BUDGET = 1_000_000
HELD = 700_000  # what the hog keeps waiting: the rest of the budget is smaller than a frame
FRAME = 600_000  # more than a read takes at once (asyncio reads 256 KiB), and than what is left
REFUSED = "incomplete messages from all connections"


@pytest.fixture(params=["on", "off"])
def shortcuts(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """The WebSocket and TCP shortcuts on (the default) and off (``RWT_NO_SHORTCUTS=1``).

    They are chosen per connection, so setting the variable here reaches them.
    """
    monkeypatch.setenv("RWT_NO_SHORTCUTS", "0" if request.param == "on" else "1")
    return str(request.param)


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    async with running_server(ServerConfig(max_fragment_memory=BUDGET)) as h:
        yield h


async def held_at_least(harness: Harness, size: int) -> None:
    """Wait until the server's budget holds ``size`` bytes (the hog's bytes were read)."""
    while harness.server.fragment_budget.used < size:
        await anyio.sleep(0.01)


async def all_given_back(harness: Harness) -> None:
    while harness.server.fragment_budget.used:
        await anyio.sleep(0.01)


def publish_frame(size: int) -> bytes:
    """A whole ``publish`` of about ``size`` bytes, refused: ``/client_count`` holds an int32."""
    op = {"op": "publish", "id": "big", "topic": "/client_count", "msg": {"data": "x" * size}}
    return json.dumps(op).encode()


async def test_a_tcp_frame_that_does_not_fit_is_skipped_and_the_connection_goes_on(
    harness: Harness, shortcuts: str
) -> None:
    hog = await harness.connect("tcp", "hog")
    client = await harness.connect("tcp")
    assert isinstance(client, StreamClient)
    frame, hogs = publish_frame(FRAME), publish_frame(2 * HELD)
    with anyio.fail_after(TIMEOUT_S):
        await hog.send_raw(hogs[:HELD])  # no end yet: kept
        await held_at_least(harness, HELD)
        await client.send_raw(frame)
        refused = await client.expect(is_op("status", level="error"))
        assert refused["msg"].startswith("frame dropped: ")
        assert REFUSED in refused["msg"] and str(BUDGET) in refused["msg"]
        await client.send({"op": "set_level", "level": "info", "id": "alive"})
        assert (await client.expect(is_op("status", id="alive")))["level"] == "info"
        await hog.send_raw(hogs[HELD:])  # whole: its bytes are given back
        await all_given_back(harness)
        await client.send_raw(frame)  # now it fits: handled (and refused for what it holds)
        answer = await client.expect(is_op("status", id="big"))
        assert answer["msg"].startswith("publish: "), answer
    assert not [m for m in client.backlog if REFUSED in m.get("msg", "")]


async def fragmented(first: str, done: anyio.Event) -> AsyncIterator[str]:
    """A fragmented text message whose last fragment waits for ``done``."""
    yield first
    await done.wait()
    yield "}"


async def send_fragmented(ws: ClientConnection, first: str, done: anyio.Event) -> None:
    """Send a fragmented message (``fragmented``); the server may close meanwhile."""
    with contextlib.suppress(ConnectionClosed):
        await ws.send(fragmented(first, done))


async def raw_websocket(harness: Harness) -> SocketStream:
    """A WebSocket connection by hand, upgraded: frames are then written as bytes."""
    stream = await anyio.connect_tcp("127.0.0.1", harness.port("websocket"))
    key = base64.b64encode(os.urandom(16)).decode()
    await stream.send(
        f"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
    )
    response = b""
    while b"\r\n\r\n" not in response:
        response += await stream.receive()
    assert response.startswith(b"HTTP/1.1 101"), response
    return stream


def text_header(length: int) -> bytes:
    """A masked text frame's header (FIN set) with an all-zero mask: the payload goes as is."""
    return bytes((0x81, 0x80 | 127)) + length.to_bytes(8, "big") + bytes(4)


async def close_frame(stream: SocketStream) -> tuple[int, str]:
    """The code and reason of the server's close frame (the only frame it sends here)."""
    data = b""
    while len(data) < 2 or len(data) < 2 + (data[1] & 0x7F):
        data += await stream.receive()
    assert data[0] == 0x88, data
    payload = data[2 : 2 + data[1]]
    return int.from_bytes(payload[:2], "big"), payload[2:].decode()


async def test_a_websocket_message_that_does_not_fit_closes_its_connection_with_1013(
    harness: Harness, shortcuts: str
) -> None:
    url = f"ws://127.0.0.1:{harness.port('websocket')}"
    done = anyio.Event()
    async with connect(url) as hog, connect(url) as client, anyio.create_task_group() as tg:
        with anyio.fail_after(TIMEOUT_S):
            tg.start_soon(send_fragmented, hog, "x" * HELD, done)
            await held_at_least(harness, HELD)
            # a frame begun: read ahead of websockets (ws-frame-reader) or by its parser
            raw = await raw_websocket(harness)
            await raw.send(text_header(FRAME + 10) + b"x" * FRAME)
            code, reason = await close_frame(raw)
            assert code == 1013
            assert REFUSED in reason
            await raw.aclose()
            # the first frames of a fragmented message
            tg.start_soon(send_fragmented, client, "y" * FRAME, done)
            with pytest.raises(ConnectionClosed) as closed:
                await client.recv()
            assert closed.value.rcvd is not None
            assert closed.value.rcvd.code == 1013
            assert REFUSED in closed.value.rcvd.reason
            done.set()  # the hog's message is whole (and not JSON): its bytes come back
            answer = json.loads(await hog.recv())
            assert answer["op"] == "status", answer
            await all_given_back(harness)


async def test_a_closed_connection_gives_back_what_its_frame_held(harness: Harness) -> None:
    tcp = await harness.connect("tcp")
    with anyio.fail_after(TIMEOUT_S):
        await tcp.send_raw(publish_frame(2 * HELD)[:HELD])
        await held_at_least(harness, HELD)
        await tcp.aclose()
        await all_given_back(harness)
        raw = await raw_websocket(harness)
        await raw.send(text_header(2 * HELD) + b"x" * HELD)
        await held_at_least(harness, HELD)
        await raw.aclose()
        await all_given_back(harness)
