"""The tools are declared once (``rwt_mcp.catalog.TOOLS``): what a server lists and refuses follows.

A server lists exactly the catalog's tools, in its order; each tool's
``readOnlyHint`` is the catalog's safety class, only the app tools carry
``_meta.ui``, and read-only mode refuses exactly the write tools (the tool error names
``--mcp-read-only``). A tool added to ``RobotTools`` without an entry, or an entry
without a method, fails here.
"""

from __future__ import annotations

import pytest

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp.server.mcpserver.exceptions import ToolError

from rwt_mcp.catalog import APP_TOOLS, TASK_TOOLS, TOOL_NAMES, TOOLS, WRITE_TOOLS
from rwt_mcp.guard import Guard
from rwt_mcp.link import RobotLink
from rwt_mcp.tools import RobotTools, build_server

pytestmark = pytest.mark.anyio


async def test_a_server_lists_the_catalog_and_its_safety_classes() -> None:
    server, _ = build_server(RobotLink("ws://127.0.0.1:9"))
    listed = await server.list_tools()
    assert [tool.name for tool in listed] == list(TOOLS)
    for tool in listed:
        spec = TOOLS[tool.name]
        assert tool.annotations is not None
        assert tool.annotations.read_only_hint is not spec.write, tool.name
        assert (tool.meta is not None and "ui" in tool.meta) is spec.app, tool.name
    assert {"robot_app"} == APP_TOOLS and {"send_action_goal"} == TASK_TOOLS
    for name in TOOLS:
        assert callable(getattr(RobotTools, name, None)), name


def test_read_only_mode_refuses_exactly_the_write_tools() -> None:
    guard = Guard(read_only=True)
    refused = set()
    for name in TOOLS:
        arguments = {}
        if name in TOOL_NAMES:
            arguments[TOOL_NAMES[name][1]] = "/a_name"
        try:
            guard.admit(name, arguments)
        except ToolError as exc:
            assert "the MCP server is read-only" in str(exc)
            refused.add(name)
    assert refused == WRITE_TOOLS
