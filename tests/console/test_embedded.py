"""An embedded `RosbridgeServer` serves the console by default, as `rwt serve` does.

By the same rule (docs/console.md, "Embedding"): on unless allowed origins are set,
off with ``WebSocketOptions(console=False)``, and the page told what the server's
settings are. examples/robot.py, the README's robot, relies on it.
"""

from __future__ import annotations

import json

import anyio
import pytest

from rwt import RosbridgeServer, ServerConfig
from rwt.server import ConsoleSite, WebSocketOptions
from tests.console.test_http import http_get
from tests.support.clients import running_server

pytestmark = pytest.mark.anyio

CONSOLE_PAGE = b'<script type="module" src="/console/main.js">'


async def get(url: str, target: str) -> tuple[int, dict[str, str], bytes]:
    return await anyio.to_thread.run_sync(http_get, url, target)


async def test_the_default_server_serves_the_console_at_its_root() -> None:
    async with running_server() as harness:
        url = f"http://127.0.0.1:{harness.port('websocket')}"
        status, fields, body = await get(url, "/")
        assert status == 200 and fields["Content-Type"] == "text/html; charset=utf-8"
        assert CONSOLE_PAGE in body
        config = json.loads((await get(url, "/console/config.json"))[2])
        assert config["websocket"] == {"port": None, "path": "/", "tls": False}
        assert config["auth"] is False
        assert config["foxglove"] is True  # Foxglove is answered on the port by default
        assert harness.server.console is not None
        ws = await harness.connect("ws")  # and the WebSocket, as before
        await ws.send({"op": "set_level", "level": "info", "id": "ws"})


@pytest.mark.parametrize(
    ("websocket", "served"),
    [
        (WebSocketOptions(console=False), False),
        (WebSocketOptions(console=None), False),
        (WebSocketOptions(allowed_origins=("https://robot.example",)), False),
        # True is the default's rule: allowed origins keep it off
        (WebSocketOptions(allowed_origins=("http://127.0.0.1:*",), console=True), False),
        # a site of one's own is served whatever the origins (as --console)
        (WebSocketOptions(allowed_origins=("http://127.0.0.1:*",), console=ConsoleSite()), True),
        (WebSocketOptions(console=ConsoleSite(websocket_path="/given")), True),
    ],
    ids=["off", "none", "origins", "origins-and-true", "origins-and-site", "own-site"],
)
async def test_when_the_console_is_off(websocket: WebSocketOptions, served: bool) -> None:
    async with running_server(ServerConfig(websocket=websocket)) as harness:
        status, _, body = await get(f"http://127.0.0.1:{harness.port('websocket')}", "/")
        assert (status == 200) is served
        assert (CONSOLE_PAGE in body) is served
        assert (harness.server.console is not None) is served


async def test_the_page_is_told_the_servers_settings() -> None:
    config = ServerConfig(websocket=WebSocketOptions(url_path="/rosbridge"))
    async with running_server(config, authenticator=lambda op, peer: True) as harness:
        url = f"http://127.0.0.1:{harness.port('websocket')}"
        page = json.loads((await get(url, "/console/config.json"))[2])
        assert page["websocket"]["path"] == "/rosbridge"
        assert page["auth"] is True  # the page asks for the auth op first


def test_a_server_made_without_serving_keeps_the_config_it_was_given() -> None:
    # the resolved site is the server's; the caller's options still say "default"
    options = WebSocketOptions()
    server = RosbridgeServer(config=ServerConfig(websocket=options))
    assert options.console is True
    assert isinstance(server.console, ConsoleSite)
    assert server.config.websocket.console is server.console
