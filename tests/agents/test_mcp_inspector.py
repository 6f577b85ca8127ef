"""The MCP Inspector's command-line mode against ``rwt serve --mcp`` and ``rwt mcp URL``.

The Inspector (npm ``@modelcontextprotocol/inspector``, pinned in tests/js) is
the MCP project's own client for checking a server: in ``--cli`` mode it
connects, makes one request and prints the answer as JSON. It lists the tools
and calls one, over Streamable HTTP at ``/mcp`` of ``rwt serve --mcp`` and over
stdio with ``rwt mcp``.
"""

from __future__ import annotations

import json
import sys

import pytest

from tests.agents.test_rwt_mcp import TOOLS
from tests.support.cli import rwt_serve
from tests.support.realclients import JS_DIR, node_missing, run_node_bin

pytestmark = pytest.mark.anyio

INSPECTOR = "mcp-inspector"
_missing = node_missing() or (
    None
    if (JS_DIR / "node_modules" / ".bin" / INSPECTOR).exists()
    else "the MCP Inspector is missing: run `npm ci --prefix tests/js`"
)
if _missing:
    pytest.skip(_missing, allow_module_level=True)


async def _inspect(*target: str, method: str, **tool: str) -> dict[str, object]:
    """One request of the Inspector (``--cli``) to ``target``; its JSON answer."""
    args = [*target, "--method", method]
    if tool:
        args += ["--tool-name", tool.pop("name")]
        for key, value in tool.items():
            args += ["--tool-arg", f"{key}={value}"]
    return json.loads(await run_node_bin(INSPECTOR, "--cli", *args))  # type: ignore[no-any-return]


async def test_the_inspector_lists_and_calls_the_tools_of_both_fronts() -> None:
    async with rwt_serve("--port", "0", "--mcp") as (_, urls):
        url = urls["ws"]
        http = (url.replace("ws://", "http://") + "/mcp", "--transport", "http")
        stdio = (sys.executable, "-m", "rwt", "mcp", url)
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
