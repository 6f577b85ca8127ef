"""The MCP Inspector's command-line mode against ``rwt serve --mcp`` and ``rwt mcp URL``.

The Inspector (npm ``@modelcontextprotocol/inspector``, pinned in tests/js/inspector
and installed once in a folder of its own: tests/support/inspector.py) is
the MCP project's own client for checking a server: in ``--cli`` mode it
connects, makes one request and prints the answer as JSON. It lists the tools
and calls one, over Streamable HTTP at ``/mcp`` of ``rwt serve --mcp`` and over
stdio with ``rwt mcp``; with ``--auth-secret-file`` it needs a bearer token, a
video token an authenticated rosbridge connection asked for.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import httpx
import pytest
from websockets.asyncio.client import connect

from rwt_protocol.auth import rosauth_mac
from tests.agents.test_rwt_mcp import TOOLS
from tests.support.cli import RWT, rwt_serve
from tests.support.inspector import inspector_bin
from tests.support.realclients import run_command

pytestmark = pytest.mark.anyio

SECRET = "1234567890abcdef"
INSPECTOR, _missing = inspector_bin()
if INSPECTOR is None:
    pytest.skip(_missing, allow_module_level=True)


async def _inspect(*target: str, method: str, **tool: str) -> dict[str, object]:
    """One request of the Inspector (``--cli``) to ``target``; its JSON answer."""
    args = [*target, "--method", method]
    if tool:
        args += ["--tool-name", tool.pop("name")]
        for key, value in tool.items():
            args += ["--tool-arg", f"{key}={value}"]
    return json.loads(await run_command(str(INSPECTOR), "--cli", *args))  # type: ignore[no-any-return]


async def test_the_inspector_lists_and_calls_the_tools_of_both_fronts() -> None:
    async with rwt_serve("--port", "0", "--mcp") as (_, urls):
        url = urls["ws"]
        http = (url.replace("ws://", "http://") + "/mcp", "--transport", "http")
        stdio = (*RWT, "mcp", url)  # forked by this worker's warm rwt
        for target in (http, stdio):
            listed = await _inspect(*target, method="tools/list")
            assert {tool["name"] for tool in listed["tools"]} == TOOLS  # type: ignore[attr-defined]
            called = await _inspect(
                *target, method="tools/call", name="echo", topic="/client_count"
            )
            assert called["isError"] is False
            summary = json.loads(called["content"][0]["text"])  # type: ignore[index]
            assert summary == {
                "topic": "/client_count",
                "type": "std_msgs/msg/Int32",
                "received": 1,
            }


async def test_with_an_auth_secret_the_inspector_needs_a_video_token(tmp_path: Path) -> None:
    secret = tmp_path / "secret"
    secret.write_text(SECRET)
    async with rwt_serve("--port", "0", "--mcp", "--auth-secret-file", str(secret)) as (_, urls):
        url = urls["ws"]
        endpoint = url.replace("ws://", "http://") + "/mcp"
        async with httpx.AsyncClient(timeout=30) as http:
            refused = await http.post(endpoint, json={"jsonrpc": "2.0", "id": 1, "method": "ping"})
        assert refused.status_code == 401 and "/rwt/video_token" in refused.text
        async with connect(url) as rosbridge:  # an authenticated connection asks for a token
            await rosbridge.send(json.dumps(_auth_op()))
            call = {"op": "call_service", "service": "/rwt/video_token", "id": "t"}
            await rosbridge.send(json.dumps(call))
            reply = json.loads(await rosbridge.recv())
        assert reply["result"] is True
        bearer = f"Authorization: Bearer {reply['values']['message']}"
        target = (endpoint, "--transport", "http", "--header", bearer)
        listed = await _inspect(*target, method="tools/list")
        assert {tool["name"] for tool in listed["tools"]} == TOOLS  # type: ignore[attr-defined]


def _auth_op() -> dict[str, object]:
    """rosauth's ``auth`` op for ``SECRET``, valid for a minute (D23)."""
    now = time.time()
    fields = {
        "client": "127.0.0.1",
        "dest": "127.0.0.1",
        "rand": "fresh-random-string",
        "t": int(now - 1),
        "level": "user",
        "end": int(now + 60),
    }
    return {"op": "auth", "mac": rosauth_mac(SECRET, **fields), **fields}  # type: ignore[arg-type]
