"""`rwt serve`'s Foxglove flags, run as a user runs them (docs/foxglove.md, "Connecting").

On its defaults the WebSocket port answers both protocols, by the subprotocol
offered; ``--foxglove-port`` adds a listener that speaks only Foxglove (its URL is
the second ``listening on`` line); ``--no-foxglove`` gives every client rosbridge.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import pytest
from anyio.streams.buffered import BufferedByteReceiveStream
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import InvalidStatus

from tests.support.cli import ENV, SERVE

pytestmark = pytest.mark.anyio


@asynccontextmanager
async def serving(*args: str, listeners: int = 1) -> AsyncIterator[list[str]]:
    """`rwt serve --port 0 --no-tf ARGS`; its listeners' URLs, in the order it prints them."""
    process = await anyio.open_process(
        [*SERVE, "--port", "0", "--no-tf", *args],
        env=ENV,
        stdin=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        assert process.stdout is not None
        stdout = BufferedByteReceiveStream(process.stdout)
        urls = []
        with anyio.fail_after(30):
            while len(urls) < listeners:
                line = (await stdout.receive_until(b"\n", 1000)).decode()
                urls.append(line.removeprefix("listening on "))
            yield urls
    finally:
        if process.returncode is None:
            process.kill()
        await process.aclose()


async def protocol_of(url: str, offered: list[str] | None) -> str:
    """What a client offering ``offered`` is answered in: 'foxglove' or 'rosbridge'."""
    async with connect(url, subprotocols=offered) as ws:  # type: ignore[arg-type]
        if ws.subprotocol is not None:
            assert ws.subprotocol == offered[0]  # type: ignore[index]
            assert json.loads(await ws.recv())["op"] == "serverInfo"
            return "foxglove"
        return await _rosbridge(ws)


async def _rosbridge(ws: ClientConnection) -> str:
    await ws.send(json.dumps({"op": "set_level", "level": "info", "id": "in"}))
    assert json.loads(await ws.recv())["id"] == "in"
    return "rosbridge"


async def test_defaults_answer_both_and_the_foxglove_port_only_foxglove() -> None:
    async with serving("--foxglove-port", "0", listeners=2) as (main, foxglove):
        assert await protocol_of(main, ["foxglove.sdk.v1"]) == "foxglove"
        assert await protocol_of(main, ["foxglove.websocket.v1"]) == "foxglove"
        assert await protocol_of(main, None) == "rosbridge"
        assert await protocol_of(foxglove, ["foxglove.websocket.v1"]) == "foxglove"
        with pytest.raises(InvalidStatus) as refused:
            await protocol_of(foxglove, None)
        assert refused.value.response.status_code == 400


async def test_no_foxglove_gives_every_client_rosbridge() -> None:
    async with serving("--no-foxglove") as (main,):
        assert await protocol_of(main, ["foxglove.sdk.v1"]) == "rosbridge"
        assert await protocol_of(main, None) == "rosbridge"
