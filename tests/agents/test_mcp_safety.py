"""``rwt serve --mcp`` and ``rwt mcp``: what an agent may not do, and what a flood cannot do.

The official MCP client (Streamable HTTP, or stdio for ``rwt mcp``) against a
robot on a free port: a new session needs a live bearer token when the server
has an auth secret; the access globs, read-only mode and the per-tool caps
refuse calls with a tool error naming the rule, and the robot hears nothing of
them; topics are resources whose updates come at a bounded rate; a WebSocket
client beside an MCP flood is still served.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import anyio
import httpx
import pytest

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_client import Ros, Service, Topic
from rwt_protocol.ratelog import EpisodeLog
from rwt_protocol.runtime import access as access_gate
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

import httpx2
from mcp import Client
from mcp.client.streamable_http import streamable_http_client
from mcp.types import ResourceUpdatedNotification, ServerNotification, TextContent

from rwt_mcp.guard import MAX_TOOL_ARGUMENT_BYTES, TOOL_BURST, TOOL_CALLS_PER_S, WRITE_TOOLS
from rwt_mcp.resources import UPDATE_INTERVAL_S
from rwt_transports.http.mcp import MAX_REQUEST_BYTES, MAX_REQUESTS_IN_FLIGHT
from rwt_transports.http.mcp_options import McpOptions
from rwt_transports.server import rosauth_authenticator
from rwt_transports.websocket import WebSocketOptions
from rwt_video import VideoTokens, install_token_service
from tests.agents.test_rwt_mcp import FIB, Message, robot_graph, rwt_mcp, rwt_serve_mcp

pytestmark = pytest.mark.anyio

INITIALIZE = {
    "jsonrpc": "2.0",
    "id": 1,
    "method": "initialize",
    "params": {
        "protocolVersion": "2025-06-18",
        "capabilities": {},
        "clientInfo": {"name": "raw", "version": "0"},
    },
}
ACCEPT = {"Accept": "application/json, text/event-stream", "Content-Type": "application/json"}
# a call of every write tool, with arguments that would work on the robot
WRITES: dict[str, dict[str, Any]] = {
    "publish": {"topic": "/cmd", "type": "std_msgs/msg/String", "msg": {"data": "go"}},
    "publish_for": {
        "topic": "/cmd",
        "type": "std_msgs/msg/String",
        "msg": {"data": "go"},
        "rate_hz": 10,
        "duration_s": 0.2,
    },
    "call_service": {"service": "/lights", "type": "std_srvs/srv/SetBool", "args": {"data": True}},
    "send_action_goal": {"action": "/fibonacci", "type": FIB, "goal": {"order": 3}},
    "cancel_action_goal": {"action": "/fibonacci", "goal_id": "g1"},
    "set_parameter": {"name": "/robot:max_speed", "value": 9.0},
}


def _text(result: Any) -> str:
    return " ".join(block.text for block in result.content if isinstance(block, TextContent))


@pytest.fixture
async def serving() -> AsyncIterator[Any]:
    """A function serving a graph with a server config in the test's task group."""
    async with anyio.create_task_group() as tg:

        async def serve(
            graph: Graph, config: ServerConfig, **kwargs: Any
        ) -> tuple[str, RosbridgeServer]:
            server = RosbridgeServer(graph, config, **kwargs)
            return await tg.start(server.serve), server

        yield serve
        tg.cancel_scope.cancel()


def _config(mcp: McpOptions | None = None, **fields: Any) -> ServerConfig:
    return ServerConfig(host="127.0.0.1", port=0, mcp=mcp or McpOptions(), **fields)


async def test_a_session_needs_a_live_bearer_token_when_the_server_has_a_secret(
    serving: Any,
) -> None:
    graph = robot_graph([])
    tokens = VideoTokens()
    install_token_service(graph, tokens)
    authenticator = rosauth_authenticator("s3cret-s3cret-s3cret", graph.clock)
    auth_server = "https://login.example.com"
    config = _config(McpOptions(bearer_token=tokens.valid, authorization_server=auth_server))
    url, server = await serving(graph, config, authenticator=authenticator)
    endpoint = url.replace("ws://", "http://") + "/mcp"
    async with httpx.AsyncClient(timeout=30) as http:
        missing = await http.post(endpoint, json=INITIALIZE, headers=ACCEPT)
        assert missing.status_code == 401
        metadata_url = url.replace("ws://", "http://") + "/.well-known/oauth-protected-resource"
        challenge = f'Bearer resource_metadata="{metadata_url}/mcp"'
        assert missing.headers["WWW-Authenticate"] == challenge  # RFC 9728 section 5.1
        assert "a bearer token is needed: call /rwt/video_token" in missing.text
        metadata = (await http.get(metadata_url + "/mcp")).json()
        assert metadata["resource"] == endpoint
        assert metadata["authorization_servers"] == ["https://login.example.com"]
        for other in ("Basic dXNlcjpwYXNz", "MAC a-rosbridge-mac"):  # other schemes: refused
            answer = await http.post(
                endpoint, json=INITIALIZE, headers={**ACCEPT, "Authorization": other}
            )
            assert answer.status_code == 401 and "is not taken here" in answer.text
            assert answer.headers["WWW-Authenticate"] == challenge
        in_url = await http.post(
            endpoint + f"?token={tokens.issue()}", json=INITIALIZE, headers=ACCEPT
        )
        assert in_url.status_code == 401 and "a token in the URL is refused" in in_url.text
        modern = {**ACCEPT, "MCP-Protocol-Version": "2026-07-28"}
        discover = {"jsonrpc": "2.0", "id": 1, "method": "server/discover", "params": {}}
        assert (await http.post(endpoint, json=discover, headers=modern)).status_code == 401
        bad = {**ACCEPT, "Authorization": "Bearer not-a-token"}
        assert (await http.post(endpoint, json=INITIALIZE, headers=bad)).status_code == 401
        assert not server.sessions  # nothing was admitted

        token = tokens.issue()
        good = {**ACCEPT, "Authorization": f"Bearer {token}"}
        opened = await http.post(endpoint, json=INITIALIZE, headers=good)
        assert opened.status_code == 200
        session_id = opened.headers["Mcp-Session-Id"]
        listing = {"jsonrpc": "2.0", "id": 2, "method": "tools/list"}
        stolen = {**bad, "Mcp-Session-Id": session_id}
        refused = await http.post(endpoint, json=listing, headers=stolen)
        assert refused.status_code == 401  # the session's id alone opens nothing
        assert "not the one that opened this MCP session" in refused.text
    async with rwt_serve_mcp(url, token=tokens.issue()) as agent:
        assert (await agent.call("get_parameter", name="/robot:max_speed"))["value"] == 1.5
    bearer = {"Authorization": f"Bearer {tokens.issue()}"}  # each 2026-07-28 request carries it
    modern_http = httpx2.AsyncClient(headers=bearer, timeout=30)
    async with Client(streamable_http_client(endpoint, http_client=modern_http), mode="auto") as c:
        assert c.protocol_version == "2026-07-28"
        assert (await c.call_tool("get_parameter", {"name": "/robot:max_speed"})).structured_content


async def test_the_access_globs_refuse_a_tool_call_naming_the_rule(serving: Any) -> None:
    received: list[Message] = []
    access = AccessPolicy(
        topics=("/battery",), services=("/allowed",), params=("/robot:name",), actions=("/none",)
    )
    config = _config(session=SessionConfig(access=access))
    url, _ = await serving(robot_graph(received), config)
    async with rwt_serve_mcp(url) as agent:
        refusals = {
            "publish": ("topic /cmd", "--topics-glob [/battery]"),
            "echo": ("topic /cmd", "--topics-glob [/battery]"),
            "call_service": ("service /lights", "--services-glob [/allowed]"),
            "get_parameter": ("name /robot:max_speed", "--params-glob [/robot:name]"),
            "send_action_goal": ("action /fibonacci", "--actions-glob [/none]"),
        }
        arguments = {
            **WRITES,
            "echo": {"topic": "/cmd", "timeout_s": 1},
            "get_parameter": {"name": "/robot:max_speed"},
        }
        for tool, (what, rule) in refusals.items():
            result = await agent.result(tool, **arguments[tool])
            assert result.is_error, tool
            assert f"{what}: refused by {rule}" in _text(result)
        assert (await agent.call("get_parameter", name="/robot:name"))["value"] == "r2"
        echoed = await agent.result("echo", topic="/battery")
        assert not echoed.is_error and json.loads(echoed.content[1].text) == {"data": "87%"}  # type: ignore[union-attr]
        with pytest.raises(Exception, match="refused by --topics-glob"):
            await agent.session.read_resource("ros://topics/cmd")  # type: ignore[arg-type]
    assert received == []


async def test_the_split_globs_hold_publishing_and_reading_apart(serving: Any) -> None:
    # --topics-pub-glob [/cmd] --topics-sub-glob [/battery] (D50)
    received: list[Message] = []
    access = AccessPolicy(topics_pub=("/cmd",), topics_sub=("/battery",))
    url, _ = await serving(robot_graph(received), _config(session=SessionConfig(access=access)))
    async with rwt_serve_mcp(url) as agent:
        assert not (await agent.result("publish", **WRITES["publish"])).is_error
        refused = await agent.result("echo", topic="/cmd", timeout_s=1)
        assert "topic /cmd: refused by --topics-sub-glob [/battery]" in _text(refused)
        battery = {"topic": "/battery", "type": "std_msgs/msg/String", "msg": {"data": "0%"}}
        refused = await agent.result("publish", **battery)
        assert "topic /battery: refused by --topics-pub-glob [/cmd]" in _text(refused)
        assert not (await agent.result("echo", topic="/battery")).is_error
    assert received == [{"data": "go"}]


@pytest.mark.parametrize("front", ["http", "stdio"])
async def test_read_only_refuses_every_write_and_the_robot_hears_none(
    serving: Any,
    front: str,
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(access_gate, "_episodes", EpisodeLog(access_gate.logger))
    caplog.set_level(logging.INFO, logger="rwt")
    received: list[Message] = []
    url, _ = await serving(robot_graph(received), _config(McpOptions(read_only=True)))
    opened = rwt_serve_mcp(url) if front == "http" else rwt_mcp(url, tmp_path, "--read-only")
    async with opened as agent:
        assert set(WRITES) == WRITE_TOOLS
        for tool, arguments in WRITES.items():
            result = await agent.result(tool, **arguments)
            assert result.is_error, tool
            assert f"{tool}: refused, the MCP server is read-only" in _text(result)
        assert (await agent.call("get_parameter", name="/robot:max_speed"))["value"] == 1.5
        assert not (await agent.result("echo", topic="/battery")).is_error
    assert received == []
    if front == "http":  # logged by the server (rwt mcp logs to its own stderr)
        [line] = _denied(caplog)  # once for the episode of six refusals
        assert "op=publish rule=--mcp-read-only reason='refused, the MCP server is" in line


def _denied(caplog: pytest.LogCaptureFixture) -> list[str]:
    """The access log's lines so far (``event=access_denied``)."""
    lines = [record.getMessage() for record in caplog.records]
    return [line for line in lines if line.startswith("event=access_denied")]


async def test_the_size_and_rate_caps_and_bad_input_are_tool_errors(
    serving: Any, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a refusal episode of its own (the access log writes one line per episode, process-wide)
    monkeypatch.setattr(access_gate, "_episodes", EpisodeLog(access_gate.logger))
    caplog.set_level(logging.INFO, logger="rwt")
    received: list[Message] = []
    url, _ = await serving(robot_graph(received), _config())
    async with rwt_serve_mcp(url) as agent:
        big = {"data": "x" * MAX_TOOL_ARGUMENT_BYTES}
        oversized = await agent.result("publish", topic="/cmd", type="std_msgs/msg/String", msg=big)
        assert oversized.is_error
        assert f"over {MAX_TOOL_ARGUMENT_BYTES} (MAX_TOOL_ARGUMENT_BYTES)" in _text(oversized)
        [line] = _denied(caplog)  # the cap's refusal in the one access log, with its rule
        assert "op=publish rule=MAX_TOOL_ARGUMENT_BYTES reason='the arguments are" in line
        wrong = await agent.result("publish", topic="/cmd", type="std_msgs/msg/String", msg="go")
        assert wrong.is_error
        assert (
            _text(wrong)
            == "publish: bad arguments: msg: Input should be a valid dictionary (got str)"
        )
        missing = await agent.result("echo", count=2)
        assert _text(missing) == "echo: bad arguments: topic: Field required"
        assert received == []
        caplog.set_level(logging.INFO, logger="rwt.mcp")
        for _ in range(3):
            await agent.call(
                "publish", topic="/cmd", type="std_msgs/msg/String", msg={"data": "go"}
            )
        writes = [r.getMessage() for r in caplog.records if "event=mcp_write" in r.getMessage()]
        assert len(writes) == 1  # once per episode, with the client
        assert writes[0].startswith("event=mcp_write client=mcp:127.0.0.1:")
        assert writes[0].endswith("tool=publish target=/cmd")

        calls, refused = 0, 0
        started = time.monotonic()
        while calls < 40 or (not refused and calls < 400):  # a loaded machine calls slower
            result = await agent.result("action_goal_status", goal_id="nope")
            assert result.is_error  # no such goal, or too fast
            calls += 1
            refused += "(TOOL_CALLS_PER_S)" in _text(result)
        elapsed = time.monotonic() - started
        assert refused >= 1
        assert calls - refused <= TOOL_BURST + TOOL_CALLS_PER_S * elapsed + 1
        assert len(_denied(caplog)) == 1  # the rate's refusals: the same episode, counted

        endpoint = url.replace("ws://", "http://") + "/mcp"
        async with httpx.AsyncClient(timeout=30) as http:
            huge = b"[" + b" " * MAX_REQUEST_BYTES + b"]"
            too_big = await http.post(endpoint, content=huge, headers=ACCEPT)
            assert too_big.status_code == 413
            assert f"over {MAX_REQUEST_BYTES} bytes" in too_big.text


@pytest.mark.parametrize("front", ["http", "stdio"])
async def test_a_subscribed_topic_is_updated_at_a_bounded_rate(
    serving: Any, front: str, tmp_path: Path
) -> None:
    graph = Graph()
    counter = graph.create_publisher("/counter", "std_msgs/msg/Int32")
    url, _ = await serving(graph, _config())
    updates: list[str] = []

    async def on_message(message: Any) -> None:
        if isinstance(message, ServerNotification) and isinstance(
            message, ResourceUpdatedNotification
        ):
            updates.append(str(message.params.uri))

    opened = (
        rwt_serve_mcp(url, on_message=on_message)
        if front == "http"
        else rwt_mcp(url, tmp_path, on_message=on_message)
    )
    async with opened as agent:
        uri = "ros://topics/counter"
        await agent.session.subscribe_resource(uri)  # type: ignore[arg-type]
        published = 0
        started = time.monotonic()
        with anyio.fail_after(30):
            while published < 300 or not updates:  # 300 messages, about 200 a second
                counter.publish({"data": published})
                published += 1
                await anyio.sleep(0.005)
        elapsed = time.monotonic() - started
        await anyio.sleep(2 * UPDATE_INTERVAL_S)  # the last update, if one was due
        read = await agent.session.read_resource(uri)  # type: ignore[arg-type]
        latest = json.loads(read.contents[0].text)  # type: ignore[union-attr]
        await agent.session.unsubscribe_resource(uri)  # type: ignore[arg-type]
    assert set(updates) == {uri}
    assert 1 <= len(updates) <= (elapsed + 2 * UPDATE_INTERVAL_S) / UPDATE_INTERVAL_S + 1
    assert len(updates) < published / 10  # far fewer than the messages
    assert 0 <= latest["data"] < published  # a message of the topic, the latest kept


async def test_a_websocket_client_is_served_through_an_mcp_flood(serving: Any) -> None:
    limit = 8
    graph = robot_graph([])
    ticks = graph.create_publisher("/ticks", "std_msgs/msg/Int32")
    url, server = await serving(graph, _config(max_connections=limit))
    endpoint = url.replace("ws://", "http://") + "/mcp"
    heard: list[Message] = []
    async with Ros(url) as bystander:
        await Topic(bystander, "/ticks", "std_msgs/msg/Int32").subscribe(heard.append)
        with anyio.fail_after(10):  # subscribed once a message comes
            while not heard:
                ticks.publish({"data": -1})
                await anyio.sleep(0.05)
        heard.clear()
        statuses: list[int] = []

        async def flood(http: httpx.AsyncClient) -> None:
            for _ in range(10):
                reply = await http.post(endpoint, json=INITIALIZE, headers=ACCEPT)
                statuses.append(reply.status_code)

        async with httpx.AsyncClient(timeout=30) as http, anyio.create_task_group() as tg:
            for _ in range(4):
                tg.start_soon(flood, http)
            for tick in range(50):
                ticks.publish({"data": tick})
                await anyio.sleep(0.01)
        answer = await Service(bystander, "/lights", "std_srvs/srv/SetBool").call({"data": True})
        assert answer["success"] is True
        with anyio.fail_after(10):
            while len(heard) < 50:
                await anyio.sleep(0.05)
        assert [msg["data"] for msg in heard] == list(range(50))
    mcp_sessions = [client for client in server.sessions if client.startswith("mcp:")]
    assert len(mcp_sessions) <= limit - 1  # the bystander holds one slot
    assert statuses.count(200) == len(mcp_sessions) and statuses.count(503) >= 1
    assert set(statuses) <= {200, 503}


async def test_a_request_outside_a_session_gets_a_status_saying_why(serving: Any) -> None:
    config = _config(websocket=WebSocketOptions(allowed_origins=("https://ok.example",)))
    url, server = await serving(robot_graph([]), config)
    endpoint = url.replace("ws://", "http://") + "/mcp"
    listing = {"jsonrpc": "2.0", "id": 2, "method": "tools/list"}
    async with httpx.AsyncClient(timeout=30) as http:
        unknown = await http.post(endpoint, json=listing, headers={**ACCEPT, "Mcp-Session-Id": "x"})
        assert unknown.status_code == 404 and "no MCP session x" in unknown.text
        stream = await http.get(endpoint, headers={"Accept": "text/event-stream"})
        assert stream.status_code == 400 and "POST an initialize request first" in stream.text
        foreign = {**ACCEPT, "Origin": "https://evil.example"}
        refused = await http.post(endpoint, json=INITIALIZE, headers=foreign)
        assert refused.status_code == 403
        assert "origin https://evil.example is not allowed" in refused.text
        allowed = await http.post(
            endpoint, json=INITIALIZE, headers={**ACCEPT, "Origin": "https://ok.example"}
        )
        assert allowed.status_code == 200
        assert allowed.headers["Access-Control-Allow-Origin"] == "https://ok.example"
        expose = allowed.headers["Access-Control-Expose-Headers"]
        assert expose == "Mcp-Session-Id, WWW-Authenticate"
        # another path is the WebSocket listener's own: no console here, so it asks for an upgrade
        assert (await http.get(url.replace("ws://", "http://") + "/mcpx")).status_code == 426
    assert [client for client in server.sessions if client.startswith("mcp:")] != []


async def test_a_session_holds_a_bounded_number_of_requests_at_once(serving: Any) -> None:
    url, server = await serving(robot_graph([]), _config())
    endpoint = url.replace("ws://", "http://") + "/mcp"
    async with httpx.AsyncClient(timeout=30) as http:
        opened = await http.post(endpoint, json=INITIALIZE, headers=ACCEPT)
        session = {
            **ACCEPT,
            "Mcp-Session-Id": opened.headers["Mcp-Session-Id"],
            "Mcp-Protocol-Version": "2025-06-18",
        }
        ready = {"jsonrpc": "2.0", "method": "notifications/initialized"}
        assert (await http.post(endpoint, json=ready, headers=session)).status_code == 202
        statuses: list[int] = []

        async def wait_on_a_quiet_topic(call_id: int) -> None:
            call = {
                "jsonrpc": "2.0",
                "id": call_id,
                "method": "tools/call",
                "params": {"name": "echo", "arguments": {"topic": "/cmd", "timeout_s": 3}},
            }
            statuses.append((await http.post(endpoint, json=call, headers=session)).status_code)

        async with anyio.create_task_group() as tg:
            for call_id in range(MAX_REQUESTS_IN_FLIGHT):
                tg.start_soon(wait_on_a_quiet_topic, 10 + call_id)
            held = server.endpoints["mcp"].sessions[session["Mcp-Session-Id"]]
            with anyio.fail_after(10):
                while held.in_flight < MAX_REQUESTS_IN_FLIGHT:
                    await anyio.sleep(0.05)
            one_more = await http.post(endpoint, json=ready, headers=session)
            assert one_more.status_code == 429
            assert (
                f"{MAX_REQUESTS_IN_FLIGHT} requests of this MCP session are in flight"
                in one_more.text
            )
        assert statuses == [200] * MAX_REQUESTS_IN_FLIGHT  # the eight were answered
        after = await http.post(endpoint, json=ready, headers=session)
        assert after.status_code == 202  # room again
