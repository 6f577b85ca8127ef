"""No authenticated client can revoke another's video tokens by asking for many (D32).

Tokens of ``/rwt/video_token`` open the video port, WebRTC offers and MCP
sessions. They were kept in a store of 256 that dropped the oldest: 256 calls by
any authenticated client made every other client's new MCP session get 401. A
signed token needs no store, so a flood of them revokes nothing.
"""

from __future__ import annotations

import time

import anyio
import pytest

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_client import Ros, Service
from rwt_protocol.auth import rosauth_mac
from rwt_transports.http.mcp_options import McpOptions
from rwt_transports.server import rosauth_authenticator
from rwt_video import VideoTokens, install_token_service
from rwt_video.tokens import TOKEN_SERVICE

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from tests.agents.test_rwt_mcp import rwt_serve_mcp

pytestmark = pytest.mark.anyio

SECRET = "s3cret-s3cret-s3cret"


async def _authenticate(ros: Ros, rand: str) -> None:
    now = time.time()
    fields = {"client": "127.0.0.1", "dest": "127.0.0.1", "rand": rand, "level": "user"}
    mac = rosauth_mac(SECRET, **fields, t=now - 1, end=now + 60)  # type: ignore[arg-type]
    await ros.authenticate(mac, fields["client"], fields["dest"], rand, now - 1, "user", now + 60)


async def test_a_token_flood_revokes_no_other_clients_token() -> None:
    graph = Graph()
    graph.params.declare("/robot", {"max_speed": 1.5})
    tokens = VideoTokens()
    install_token_service(graph, tokens)
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions(bearer_token=tokens.valid))
    authenticator = rosauth_authenticator(SECRET, graph.clock)
    async with anyio.create_task_group() as tg:
        url = await tg.start(RosbridgeServer(graph, config, authenticator=authenticator).serve)
        async with Ros(url) as victim, Ros(url) as attacker:
            await _authenticate(victim, "victim-rand")
            await _authenticate(attacker, "attacker-rand")
            with anyio.fail_after(30):
                token = str((await Service(victim, TOKEN_SERVICE).call())["message"])
                flood = Service(attacker, TOKEN_SERVICE)
                for _ in range(300):  # more than the 256 the store kept
                    assert (await flood.call())["success"] is True
                # main: HTTP 401, the victim's token pushed out of the store
                async with rwt_serve_mcp(url, token=token) as agent:
                    answer = await agent.call("get_parameter", name="/robot:max_speed")
                    assert answer["value"] == 1.5
        tg.cancel_scope.cancel()
