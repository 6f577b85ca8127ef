"""What an MCP session may cost the server, and what it hears of a refusal.

The official MCP client against ``rwt serve --mcp`` in the test's process (its
images: tests/hardening/test_image_work.py):

- listings of a large graph are cheap and rated, ``resources/list`` pages with
  MCP's cursor;
- a refused ``set_parameter`` or subscription is a tool error with the server's
  reason, never a quiet success or a timeout, and so is ``--max-subscriptions``.
"""

from __future__ import annotations

import json
import logging
import re
import threading
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import anyio
import httpx
import pytest

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_protocol.server.session import SessionConfig

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp.shared.exceptions import MCPError
from mcp.types import PaginatedRequestParams, TextContent

from rwt_mcp.guard import LISTING_BURST, LISTING_CALLS_PER_S
from rwt_mcp.resources import RESOURCES_PER_PAGE
from rwt_transports.http.mcp_options import McpOptions
from tests.agents.test_rwt_mcp import Agent, rwt_serve_mcp

pytestmark = pytest.mark.anyio


@asynccontextmanager
async def serving(graph: Graph, **session: Any) -> AsyncIterator[str]:
    """``graph`` served with MCP on a free port (``session``: SessionConfig fields)."""
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions())
    if session:
        config = ServerConfig(
            host="127.0.0.1", port=0, mcp=McpOptions(), session=SessionConfig(**session)
        )
    async with anyio.create_task_group() as tg:
        yield await tg.start(RosbridgeServer(graph, config).serve)
        tg.cancel_scope.cancel()


def _text(result: Any) -> str:
    return " ".join(block.text for block in result.content if isinstance(block, TextContent))


def _post(http: httpx.Client, session: dict[str, str], body: dict[str, Any]) -> dict[str, Any]:
    """One JSON-RPC request of a raw MCP client; the response (JSON or an SSE event)."""
    answer = http.post("/mcp", json=body, headers=session)
    if answer.headers.get("content-type", "").startswith("text/event-stream"):
        data = [line[5:] for line in answer.text.splitlines() if line.startswith("data:")]
        return dict(json.loads(data[-1]))
    return dict(answer.json()) if answer.content else {}


def _flood(base: str, sessions: int, seconds: float, results: list[list[bool]]) -> None:
    """``sessions`` raw MCP clients calling ``list_topics`` 10 times a second (its tool cap).

    Runs in a thread of its own (its own event loop, httpx's sync client): the
    server's event loop thread does only the server's work meanwhile.
    """
    accept = {"Accept": "application/json, text/event-stream"}
    init = {
        "jsonrpc": "2.0",
        "id": 0,
        "method": "initialize",
        "params": {
            "protocolVersion": "2025-06-18",
            "capabilities": {},
            "clientInfo": {"name": "f"},
        },
    }
    with httpx.Client(base_url=base, timeout=30) as http:
        heads = []
        for _ in range(sessions):
            opened = http.post("/mcp", json=init, headers=accept)
            head = {**accept, "Mcp-Session-Id": opened.headers["Mcp-Session-Id"]}
            head["Mcp-Protocol-Version"] = "2025-06-18"
            _post(http, head, {"jsonrpc": "2.0", "method": "notifications/initialized"})
            heads.append(head)
            results.append([])
        call = {"jsonrpc": "2.0", "method": "tools/call", "params": {"name": "list_topics"}}
        started = time.monotonic()
        for tick in range(int(seconds * 10)):
            for head, answers in zip(heads, results, strict=True):
                answer = _post(http, head, {**call, "id": tick + 1})
                answers.append(not answer["result"].get("isError", False))
            time.sleep(max(0.0, started + (tick + 1) / 10 - time.monotonic()))


async def test_listings_of_a_large_graph_are_cheap_and_rated() -> None:
    """4 sessions calling list_topics at their tool cap on 2000 topics: little of the loop's CPU.

    (Before: 4 such sessions took 90 % of a core, and a rosbridge client's round
    trips went from 1.5 ms to 124 ms.)
    """
    graph = Graph()
    keep = [
        graph.create_publisher(f"/robot/sensor_{i:04d}/data", "std_msgs/msg/String")
        for i in range(2000)
    ]
    async with serving(graph) as url:
        base = url.replace("ws://", "http://")
        results: list[list[bool]] = []
        seconds = 2.0
        flood = threading.Thread(target=_flood, args=(base, 4, seconds, results))
        loop_cpu, started = time.thread_time(), time.monotonic()
        flood.start()
        while flood.is_alive():
            await anyio.sleep(0.05)
        loop_cpu, elapsed = time.thread_time() - loop_cpu, time.monotonic() - started
    assert len(keep) == 2000 and len(results) == 4
    calls = sum(len(answers) for answers in results)
    assert calls == 4 * int(seconds * 10)
    for answers in results:  # each session's listings within their bucket
        assert 1 <= sum(answers) <= LISTING_BURST + LISTING_CALLS_PER_S * elapsed + 1
    # main: ~48 ms of the event loop's CPU per call (its JSON schema check of 1000 topics)
    assert loop_cpu / calls < 0.02, (loop_cpu, calls)


async def test_resources_are_listed_a_page_at_a_time() -> None:
    graph = Graph()
    names = [f"/t/{i:04d}" for i in range(RESOURCES_PER_PAGE * 2 + 5)]
    keep = [graph.create_publisher(name, "std_msgs/msg/Int32") for name in names]
    async with serving(graph) as url, rwt_serve_mcp(url) as agent:
        listed: list[str] = []
        cursor = None
        for _ in range(3):
            page = await agent.session.list_resources(params=PaginatedRequestParams(cursor=cursor))
            assert len(page.resources) <= RESOURCES_PER_PAGE
            listed += [resource.name for resource in page.resources]
            cursor = page.next_cursor
        assert cursor is None  # the last page says so
        assert [name for name in listed if name.startswith("/t/")] == names
        with pytest.raises(MCPError, match="not a cursor of this server's resources/list"):
            await agent.session.list_resources(params=PaginatedRequestParams(cursor="bm9wZQ"))
        with pytest.raises(MCPError, match=r"listings called more than 2 times a second"):
            for _ in range(LISTING_BURST + 2):  # rated with the listing tools
                await agent.session.list_resources()
    assert len(keep) == len(names)


def _robot() -> Graph:
    graph = Graph()
    graph.params.declare("/robot", {"max_speed": 1.5})
    for topic in ("/battery", "/odom", "/scan"):
        graph.create_publisher(topic, "std_msgs/msg/String", latch=True).publish({"data": topic})
    return graph


async def _refused_text(agent: Agent, tool: str, **arguments: object) -> str:
    result = await agent.result(tool, **arguments)
    assert result.is_error, result.content
    return _text(result)


async def test_a_refused_set_or_subscription_is_a_tool_error_saying_why(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    async with serving(_robot()) as url, rwt_serve_mcp(url) as agent:
        with anyio.fail_after(20):
            # main: success, value null (rosapi answered successful: false)
            text = await _refused_text(agent, "set_parameter", name="/ghost:gain", value=2)
            assert "set_param /ghost:gain refused by the server: node /ghost does not exist" in text
            # main: {"timed_out": true} after timeout_s (the server's error status unheard)
            wrong = await _refused_text(
                agent, "echo", topic="/battery", type="std_msgs/msg/Int32", timeout_s=10
            )
            assert "echo /battery: the server refused the subscription: subscribe:" in wrong
            assert "is established with type std_msgs/msg/String" in wrong
            assert (await agent.call("get_parameter", name="/robot:max_speed"))["value"] == 1.5
    # no log line per request (main: the SDK's "Processing request of type ..." at INFO)
    assert not [r for r in caplog.records if r.getMessage().startswith("Processing request")]


async def test_max_subscriptions_binds_an_mcp_session_and_says_so() -> None:
    async with serving(_robot(), max_subscriptions=2) as url, rwt_serve_mcp(url) as agent:
        await _subscriptions_refused(agent)


async def _subscriptions_refused(agent: Agent) -> None:
    with anyio.fail_after(20):
        await agent.session.subscribe_resource("ros://topics/battery")  # type: ignore[arg-type]
        await agent.session.subscribe_resource("ros://topics/odom")  # type: ignore[arg-type]
        limit = "subscriptions: this connection holds 2 already (the server's limit)"
        with pytest.raises(MCPError, match="the server refused the subscription") as refused:
            await agent.session.subscribe_resource("ros://topics/scan")  # type: ignore[arg-type]
        assert limit in str(refused.value)  # main: success, and no update ever
        text = await _refused_text(agent, "echo", topic="/scan", timeout_s=10)
        assert f"echo /scan: the server refused the subscription: subscribe: {limit}" in text
        with pytest.raises(MCPError, match=re.escape(limit)):
            await agent.session.read_resource("ros://topics/scan")  # type: ignore[arg-type]
        await agent.session.unsubscribe_resource("ros://topics/odom")  # type: ignore[arg-type]
        echoed = await agent.result("echo", topic="/scan")  # room again
        assert not echoed.is_error and json.loads(echoed.content[1].text) == {"data": "/scan"}  # type: ignore[union-attr]
