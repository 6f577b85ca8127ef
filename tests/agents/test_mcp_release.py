"""A 2026-07-28 request's server goes when its request does, without the cyclic collector.

Each such request builds an MCP server (``rwt_mcp.tools.build_server``); left as a cycle,
a flood's servers were collected in batches that stopped the event loop for every other
client (benchmarks B25). ``release_server`` empties it once it answers nothing more, and
the request's exchange ends the SDK's watcher of its socket rather than leave it canceled.
"""

from __future__ import annotations

import contextlib
import gc
import json
import weakref

import anyio
import pytest

from rwt import RosbridgeServer, ServerConfig

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from rwt_mcp.link import RobotLink
from rwt_mcp.tools import build_server, release_server
from rwt_transports.http.mcp_options import McpOptions
from tests.agents.test_rwt_mcp import robot_graph


def _built() -> weakref.ref[object]:
    server, _ = build_server(RobotLink("ws://127.0.0.1:9"))
    release_server(server)
    return weakref.ref(server)


def _kept() -> weakref.ref[object]:
    server, _ = build_server(RobotLink("ws://127.0.0.1:9"))
    return weakref.ref(server)


def test_a_released_server_is_freed_by_its_last_reference() -> None:
    gc.collect()
    gc.disable()
    try:
        released, kept = _built(), _kept()
        assert released() is None  # gone as the function returned
        assert kept() is not None  # a cycle: it waits for the collector (what was fixed)
    finally:
        gc.enable()
    gc.collect()
    assert kept() is None


def _post(port: int, body: bytes) -> bytes:
    head = (
        f"POST /mcp HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
        "Accept: application/json, text/event-stream\r\nContent-Type: application/json\r\n"
        "MCP-Protocol-Version: 2026-07-28\r\nMcp-Method: tools/call\r\nMcp-Name: echo\r\n"
        f"Content-Length: {len(body)}\r\n\r\n"
    )
    return head.encode() + body


@pytest.mark.anyio
async def test_a_2026_request_leaves_no_canceled_task_for_the_collector() -> None:
    # The SDK watches each request's socket for a disconnect in a task of its own; canceled
    # at the answer's end, such a task is a cycle (its CancelledError holds its frames).
    # The exchange ends it instead: it returns once the answer has gone out.
    meta = {
        "io.modelcontextprotocol/protocolVersion": "2026-07-28",
        "io.modelcontextprotocol/clientCapabilities": {},
    }
    call = {"name": "echo", "arguments": {"topic": "/battery"}, "_meta": meta}
    body = json.dumps({"jsonrpc": "2.0", "id": 1, "method": "tools/call", "params": call})
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions())
    server = RosbridgeServer(robot_graph([]), config)
    with anyio.fail_after(30):
        async with anyio.create_task_group() as tg:
            url = await tg.start(server.serve)
            port = int(url.rsplit(":", 1)[1])
            gc.collect()
            gc.disable()
            try:
                for _ in range(3):
                    async with await anyio.connect_tcp("127.0.0.1", port) as stream:
                        await stream.send(_post(port, body.encode()))
                        answer = b""
                        with contextlib.suppress(anyio.EndOfStream):
                            while True:
                                answer += await stream.receive()
                        assert b"87%" in answer, answer[-300:]  # /battery's latched message
                await anyio.sleep(0.3)  # each request's tasks end
                gc.set_debug(gc.DEBUG_SAVEALL)
                gc.collect()
                frames = {o.f_code.co_name for o in gc.garbage if type(o).__name__ == "frame"}
            finally:
                gc.set_debug(0)
                gc.garbage.clear()
                gc.enable()
            tg.cancel_scope.cancel()
    assert "watch_disconnect" not in frames
