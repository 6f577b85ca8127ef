"""Client connectors: the TCP connection splits a JSON and CBOR stream cut anywhere (D22)."""

from __future__ import annotations

import json
import sys

import anyio
import cbor2
import pytest
from anyio.abc import SocketStream

from rwt_client.connectors import ConnectionClosedError, StdioConnection, connect, server_url
from rwt_protocol.errors import ConfigError

OBJECTS = [
    {"op": "publish", "msg": {"data": 'a"}\\{[' + str(i)}, "l": [1, [2, {}]]} for i in range(12)
]
CBOR_ITEM = cbor2.dumps({"op": "publish", "topic": "/t", "msg": {"data": b"\x00\n{"}})
TEXT = "".join(json.dumps(o) + ("\n" if i % 2 else "") for i, o in enumerate(OBJECTS))


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_tcp_connection_sends_lines_and_splits_what_it_receives() -> None:
    request = b'{"op": "subscribe",  "topic": "/t"}\n' + CBOR_ITEM
    received = bytearray()

    async def serve(stream: SocketStream) -> None:
        async with stream:
            while len(received) < len(request):
                received.extend(await stream.receive())
            reply = TEXT.encode() + CBOR_ITEM
            for start in range(0, len(reply), 7):  # concatenated, cut anywhere
                await stream.send(reply[start : start + 7])

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with listener, anyio.create_task_group() as tg:
        tg.start_soon(listener.serve, serve)
        conn = await connect(f"tcp://127.0.0.1:{port}")
        await conn.send('{"op": "subscribe",\n "topic": "/t"}')
        await conn.send(CBOR_ITEM)  # a CBOR item goes as it is (D22)
        with anyio.fail_after(5):
            frames = [json.loads(await conn.receive()) for _ in OBJECTS]
            item = await conn.receive()
        assert frames == OBJECTS
        assert bytes(received) == request
        assert item == CBOR_ITEM  # CBOR items come back as bytes
        await conn.aclose()
        tg.cancel_scope.cancel()


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_unreachable_servers_and_bad_urls() -> None:
    with pytest.raises(ConnectionClosedError, match="cannot connect"):
        await connect("ws://127.0.0.1:1")
    with pytest.raises(ValueError, match="unsupported URL scheme"):
        await connect("http://127.0.0.1:1")


def test_every_form_of_a_server_address_is_read_by_one_parser() -> None:
    """The client, rwt conformance and rwt record take the same forms (server_url)."""
    assert server_url("127.0.0.1:9090") == "ws://127.0.0.1:9090"
    assert server_url("[::1]:9090") == "ws://[::1]:9090"
    assert server_url("127.0.0.1:9090", "tcp") == "tcp://127.0.0.1:9090"
    assert server_url("ws://h:1/path", "tcp") == "tcp://h:1"
    assert server_url("tcp://h:1", "ws") == "ws://h:1"
    assert server_url("wss://h:1", "tcp") == "tcp+tls://h:1"
    assert server_url("tcp+tls://h:1", "ws") == "wss://h:1"
    assert server_url("wss://robot.example.com/rosbridge") == "wss://robot.example.com/rosbridge"
    forms = (
        "use ws://, wss://, tcp:// or tcp+tls://HOST:PORT, webrtc+http://HOST:PORT/webrtc,"
        " or HOST:PORT"
    )
    refused = {
        "http://h:9090": f"unsupported URL scheme 'http' in 'http://h:9090': {forms}",
        "localhost": f"'localhost' names no port: {forms}",
        "tcp://h": f"'tcp://h' names no port: {forms}",
        "ws://:9090": f"'ws://:9090' names no host: {forms}",
        "h:99999": "'h:99999': the port is not a number in 0-65535",
    }
    for text, message in refused.items():
        with pytest.raises(ConfigError) as caught:
            server_url(text)
        assert str(caught.value) == message


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_stdio_connection_carries_json_lines_only() -> None:
    conn = await StdioConnection.open(
        [sys.executable, "-c", "import sys; sys.stdout.write(sys.stdin.readline())"]
    )
    try:
        with pytest.raises(ConnectionClosedError, match="JSON text only"):
            await conn.send(CBOR_ITEM)
        await conn.send('{"op": "status"}')
        with anyio.fail_after(10):
            assert json.loads(await conn.receive()) == {"op": "status"}
    finally:
        await conn.aclose()
