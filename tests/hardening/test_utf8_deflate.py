"""Text that is not UTF-8 closes with 1007 (RFC 6455 8.1): a real websockets client,
with and without permessage-deflate."""

from __future__ import annotations

from collections.abc import AsyncIterator

import anyio
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from rwt_transports.server import RosbridgeServer, ServerConfig
from rwt_transports.websocket import WebSocketOptions

pytestmark = pytest.mark.anyio

TIMEOUT_S = 10
INVALID = b'{"op":"publish","topic":"/a","msg":{"data":"\xc3\x28"}}'  # 0xC3 0x28: not UTF-8


@pytest.fixture(params=[False, True], ids=["plain", "deflate"])
async def url(request: pytest.FixtureRequest) -> AsyncIterator[str]:
    options = WebSocketOptions(compression=request.param)
    server = RosbridgeServer(config=ServerConfig(port=0, websocket=options))
    async with anyio.create_task_group() as tg:
        yield await tg.start(server.serve)
        server.stop()


async def assert_closed_1007(url: str, message: bytes | list[bytes]) -> None:
    async with connect(url) as ws:  # offers permessage-deflate
        await ws.send('{"op":"set_level","level":"info","id":"before"}')
        assert "before" in str(await ws.recv())
        await ws.send(message, text=True)  # type: ignore[arg-type]
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                await ws.recv()
    assert closed.value.rcvd is not None
    assert closed.value.rcvd.code == 1007


@pytest.mark.parametrize(
    "message",
    [INVALID, [INVALID[:45], INVALID[45:]], [b'{"op":"status","msg":"\xf0\x9f', b'"}']],
    ids=["whole", "fragmented", "split-sequence-cut"],
)
async def test_invalid_utf8_text_closes_with_1007(url: str, message: bytes | list[bytes]) -> None:
    with anyio.fail_after(TIMEOUT_S):
        await assert_closed_1007(url, message)
        async with connect(url) as ws:  # the next client is served
            await ws.send('{"op":"call_service","service":"/rosapi/topics","id":"t"}')
            assert '"service_response"' in str(await ws.recv())


async def test_valid_utf8_split_across_fragments_is_served(url: str) -> None:
    text = '{"op":"set_level","level":"info","id":"\u00e9\U0001f600"}'.encode()
    cut = text.index(b"\xf0") + 2  # inside the four-byte sequence
    with anyio.fail_after(TIMEOUT_S):
        async with connect(url) as ws:
            await ws.send([text[:cut], text[cut:]], text=True)  # type: ignore[arg-type]
            assert "\U0001f600" in str(await ws.recv())
