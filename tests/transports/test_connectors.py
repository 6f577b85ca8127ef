"""Client connectors: the TCP connection splits a JSON stream cut anywhere (D22)."""

from __future__ import annotations

import json

import anyio
import pytest
from anyio.abc import SocketStream

from rwt_transports.connectors import ConnectionClosed, connect

OBJECTS = [
    {"op": "publish", "msg": {"data": 'a"}\\{[' + str(i)}, "l": [1, [2, {}]]} for i in range(12)
]
TEXT = "".join(json.dumps(o) + ("\n" if i % 2 else "") for i, o in enumerate(OBJECTS))


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_tcp_connection_sends_lines_and_splits_what_it_receives() -> None:
    received: list[bytes] = []

    async def serve(stream: SocketStream) -> None:
        async with stream:
            received.append(await stream.receive())
            for start in range(0, len(TEXT), 7):  # concatenated, cut anywhere
                await stream.send(TEXT[start : start + 7].encode())

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with listener, anyio.create_task_group() as tg:
        tg.start_soon(listener.serve, serve)
        conn = await connect(f"tcp://127.0.0.1:{port}")
        await conn.send('{"op": "subscribe",\n "topic": "/t"}')
        with anyio.fail_after(5):
            frames = [json.loads(await conn.receive()) for _ in OBJECTS]
        assert frames == OBJECTS
        assert received == [b'{"op": "subscribe",  "topic": "/t"}\n']
        with pytest.raises(ConnectionClosed):
            await conn.send(b"\x00")
        await conn.aclose()
        tg.cancel_scope.cancel()


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_unreachable_servers_and_bad_urls() -> None:
    with pytest.raises(ConnectionClosed, match="cannot connect"):
        await connect("ws://127.0.0.1:1")
    with pytest.raises(ValueError, match="unsupported URL scheme"):
        await connect("http://127.0.0.1:1")
