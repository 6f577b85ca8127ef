"""A host's new MCP sessions are paced (``HOST_SESSIONS_PER_S``): waited for, then refused.

Each 2026-07-28 request, and each 2025-era ``initialize``, opens a rosbridge session and
builds an MCP server: tens of ms of the event loop a burst. The endpoint spaces a host's
at ``1 / HOST_SESSIONS_PER_S`` s; one that comes early waits its turn (up to
``HOST_SESSION_WAIT_S``), past that it is refused before anything is built: a tool call
as a tool error naming the bound, in the one access log once per episode. An agent
calling tools one after another is never refused; another host is not slowed.
"""

from __future__ import annotations

import json
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import pytest

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.runtime import access as access_gate

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

import httpx2
from mcp import Client

from rwt_transports.http import mcp as mcp_http
from rwt_transports.http.host_rates import HostPace, host_of
from rwt_transports.http.mcp_options import McpOptions

pytestmark = pytest.mark.anyio

HEADERS = {
    "Accept": "application/json, text/event-stream",
    "MCP-Protocol-Version": "2026-07-28",
    "Mcp-Method": "tools/call",
    "Mcp-Name": "echo",
}
META = {
    "io.modelcontextprotocol/protocolVersion": "2026-07-28",
    "io.modelcontextprotocol/clientCapabilities": {},
}
CALL = {
    "jsonrpc": "2.0",
    "id": 7,
    "method": "tools/call",
    "params": {"name": "echo", "arguments": {"topic": "/battery"}, "_meta": META},
}

TOOLS = [  # three tools in turn: 20 sessions a second are under 10 calls of each
    ("echo", {"topic": "/battery"}),
    ("type_definition", {"type": "std_msgs/msg/String"}),
    ("get_parameter", {"name": "/robot:speed"}),
]


@pytest.fixture
async def endpoint() -> AsyncIterator[str]:
    """``/mcp`` of an in-process ``rwt serve --mcp`` with a latched ``/battery``."""
    async with serving() as url:
        yield url


@asynccontextmanager
async def serving() -> AsyncIterator[str]:
    """``endpoint``'s server, as a context (made after a test's settings)."""
    graph = Graph()
    graph.create_publisher("/battery", "std_msgs/msg/String", latch=True).publish({"data": "87%"})
    server = RosbridgeServer(graph, ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions()))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield "http://" + url.split("://", 1)[1] + "/mcp"
        tg.cancel_scope.cancel()


async def _call(endpoint: str, host: str) -> dict[str, object]:
    """One raw 2026-07-28 ``tools/call`` of ``echo`` from ``host``: its JSON-RPC answer."""
    transport = httpx2.AsyncHTTPTransport(local_address=host)
    async with httpx2.AsyncClient(transport=transport, timeout=30) as http:
        answer = await http.post(endpoint, json=CALL, headers=HEADERS)
    assert answer.status_code == 200, answer.text
    return dict(json.loads(answer.text))


async def test_an_agent_calling_tools_one_after_another_is_never_refused(endpoint: str) -> None:
    calls = int(mcp_http.HOST_SESSIONS_PER_S * 2)  # two seconds' worth, back to back
    with anyio.fail_after(60):
        async with Client(endpoint, mode="auto") as agent:
            assert agent.protocol_version == "2026-07-28"
            for n in range(calls):  # each a session of its own: paced, never refused
                tool, arguments = TOOLS[n % len(TOOLS)]  # each tool within its own cap
                result = await agent.call_tool(tool, arguments)
                assert not result.is_error, result.content


async def test_a_burst_past_its_wait_is_refused_as_a_tool_error_and_logged_once(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(access_gate, "_episodes", EpisodeLog(access_gate.logger))
    caplog.set_level(logging.INFO, logger="rwt")
    # no waiting for a turn: every call of a burst but the first is refused
    monkeypatch.setattr(mcp_http, "HOST_SESSION_WAIT_S", 0.0)
    answers: list[dict[str, object]] = []

    async def one(endpoint: str) -> None:
        answers.append(await _call(endpoint, "127.0.0.1"))

    with anyio.fail_after(60):
        async with serving() as endpoint:
            async with anyio.create_task_group() as tg:
                for _ in range(10):
                    tg.start_soon(one, endpoint)
            other = await _call(endpoint, "127.0.0.2")  # another host: its own pace
    results = [answer["result"] for answer in answers]
    refused = [r for r in results if isinstance(r, dict) and r.get("isError")]
    assert refused, results  # ten at once from one host: not all of them had their turn
    assert len(refused) < len(results)  # the first had it
    for result in refused:
        text = result["content"][0]["text"]  # type: ignore[index]
        assert text == (
            "Error executing tool echo: echo: over 20 MCP sessions a second from this host"
            " (HOST_SESSIONS_PER_S): wait and call again"
        )
    assert all(answer["id"] == 7 for answer in answers)
    assert not other["result"]["isError"]  # type: ignore[index]
    lines = [r.getMessage() for r in caplog.records if "rule=HOST_SESSIONS_PER_S" in r.getMessage()]
    assert len(lines) == 1  # once per episode
    assert lines[0].startswith("event=access_denied client=mcp:127.0.0.1:")


def test_the_pace_spaces_a_hosts_turns_and_forgets_old_hosts() -> None:
    now = [100.0]
    pace = HostPace(10.0, 0.25, kept=3, clock=lambda: now[0])
    assert [pace.turn("10.0.0.1:5") for _ in range(3)] == pytest.approx([0.0, 0.1, 0.2])
    assert pace.turn("10.0.0.1:6") is None  # 0.3 s away: over the wait, and takes no turn
    assert pace.turn("10.0.0.2:5") == 0.0  # another host: its own turns
    now[0] += 1.0  # a quiet second: the host starts afresh
    assert pace.turn("10.0.0.1:7") == 0.0
    for host in ("a", "b", "c", "d"):
        pace.turn(f"{host}:1")
    assert len(pace._due) == 3  # bounded whatever the number of hosts
    assert host_of("[::1]:5000") == "[::1]" and host_of("10.0.0.1:1") == "10.0.0.1"
