"""``rwt mcp URL`` and ``rwt serve --mcp``, rwt's own MCP server, driven by the official MCP client.

An rwt server runs a small robot on a free port (a latched topic, a subscriber,
a service, an action whose long goals run until canceled, parameters, a camera
image and a static transform). The official MCP Python client starts ``rwt mcp
ws://...`` as a stdio server, or reaches the server's own ``/mcp`` over
Streamable HTTP, lists the tools and calls each of them, checking
what an agent would read: messages, a publish the robot received, a service's
answer, a goal's progress notifications and result, a cancel, parameters, an
image as image content, a transform, and a refused call as a tool error.
"""

from __future__ import annotations

import base64
import io
import json
import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import httpx
import pytest

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_graph.actions import GoalCanceledError, GoalContext
from tests.support.cli import ENV, RWT, invoke_rwt

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp import ClientSession, StdioServerParameters
from mcp.client.session import MessageHandlerFnT as MessageHandler
from mcp.client.stdio import stdio_client
from mcp.client.streamable_http import streamable_http_client
from mcp.types import CallToolResult, ImageContent, TextContent
from PIL import Image

from rwt_mcp.tools import MAX_ECHO_COUNT
from rwt_transports.http.mcp_options import McpOptions

pytestmark = pytest.mark.anyio

FIB = "example_interfaces/action/Fibonacci"
HOLD_ORDER = 100  # a goal of this order runs until canceled
WIDTH, HEIGHT = 4, 2
TOOLS = {
    "list_topics",
    "list_services",
    "list_nodes",
    "list_actions",
    "list_parameters",
    "type_definition",
    "echo",
    "publish",
    "publish_for",
    "call_service",
    "send_action_goal",
    "cancel_action_goal",
    "action_goal_status",
    "get_parameter",
    "set_parameter",
    "lookup_transform",
    "robot_app",
}

Message = dict[str, Any]


def robot_graph(received: list[Message]) -> Graph:
    """The robot: topics, a service, an action, parameters, a camera and a transform."""
    graph = Graph()
    graph.params.declare("/robot", {"max_speed": 1.5, "name": "r2", "path": [0.5] * 100})
    battery = graph.create_publisher("/battery", "std_msgs/msg/String", latch=True, node="/robot")
    battery.publish({"data": "87%"})
    scan = graph.create_publisher("/scan_like", "std_msgs/msg/Float32MultiArray", latch=True)
    scan.publish({"data": [0.5] * 1000})
    graph.create_subscription("/cmd", received.append, "std_msgs/msg/String", node="/robot")
    graph.create_service(
        "/lights", "std_srvs/srv/SetBool", lambda req: {"success": req["data"]}, node="/robot"
    )
    camera = graph.create_publisher("/camera/image", "sensor_msgs/msg/Image", latch=True)
    red = bytes([255, 0, 0]) * (WIDTH * HEIGHT)
    camera.publish(
        {"encoding": "rgb8", "width": WIDTH, "height": HEIGHT, "step": WIDTH * 3, "data": red}
    )
    tf_static = graph.create_publisher("/tf_static", "tf2_msgs/msg/TFMessage", latch=True)
    link = {"header": {"frame_id": "base_link"}, "child_frame_id": "camera"}
    moved = {"translation": {"x": 0.1, "y": 0.0, "z": 0.3}, "rotation": {"w": 1.0}}
    tf_static.publish({"transforms": [{**link, "transform": moved}]})

    async def fibonacci(goal: Message, context: GoalContext) -> Message:
        sequence = [0, 1]
        if goal["order"] >= HOLD_ORDER:
            while not context.cancel_requested:
                await anyio.sleep(0.01)
            raise GoalCanceledError
        for _ in range(1, goal["order"]):
            sequence.append(sequence[-1] + sequence[-2])
            context.publish_feedback({"sequence": sequence})
            await anyio.sleep(0.02)  # feedback the MCP client can see arrive
        return {"sequence": sequence}

    graph.create_action_server("/fibonacci", FIB, fibonacci, node="/robot")
    return graph


@pytest.fixture
async def served() -> AsyncIterator[tuple[str, list[Message]]]:
    """rwt serving the robot on a free port, MCP too: ``(URL, messages /cmd received)``."""
    received: list[Message] = []
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions())
    server = RosbridgeServer(robot_graph(received), config)
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield url, received
        tg.cancel_scope.cancel()


class Agent:
    """An MCP client session with ``rwt mcp`` or ``rwt serve --mcp``."""

    def __init__(self, session: ClientSession) -> None:
        self.session = session

    async def result(self, tool: str, **arguments: object) -> CallToolResult:
        return await self.session.call_tool(tool, arguments)

    async def call(self, tool: str, **arguments: object) -> Any:
        """The tool's structured answer; fails the test on a tool error."""
        result = await self.result(tool, **arguments)
        assert not result.is_error, result.content
        assert result.structured_content is not None
        return result.structured_content


@asynccontextmanager
async def rwt_mcp(
    url: str, tmp_path: Path, *options: str, on_message: MessageHandler | None = None
) -> AsyncIterator[Agent]:
    """``rwt mcp URL [OPTIONS]`` (this checkout's) started by the official MCP client over stdio."""
    params = StdioServerParameters(  # forked by this worker's warm rwt (tests/support/cli.py)
        command=RWT[0],
        args=[*RWT[1:], "mcp", url, *options],
        env=ENV,
        cwd=str(tmp_path),
    )
    with (tmp_path / "rwt-mcp.log").open("w") as errlog:
        async with (
            stdio_client(params, errlog=errlog) as (read, write),
            ClientSession(read, write, message_handler=on_message) as session,
        ):
            await session.initialize()
            yield Agent(session)
    # the session ended (stdin closed): rwt mcp closed its connection and left quietly
    assert "Traceback" not in (tmp_path / "rwt-mcp.log").read_text()


@asynccontextmanager
async def rwt_serve_mcp(
    url: str, token: str | None = None, on_message: MessageHandler | None = None
) -> AsyncIterator[Agent]:
    """The official MCP client over Streamable HTTP at ``/mcp`` (``rwt serve --mcp``)."""
    headers = {} if token is None else {"Authorization": f"Bearer {token}"}
    endpoint = url.replace("ws://", "http://", 1) + "/mcp"
    http = httpx.AsyncClient(headers=headers, timeout=httpx.Timeout(30, read=300))
    async with (
        http,
        streamable_http_client(endpoint, http_client=http) as (read, write),
        ClientSession(read, write, message_handler=on_message) as session,
    ):
        await session.initialize()
        yield Agent(session)


@pytest.fixture(params=["stdio", "http"])
async def agent(
    request: pytest.FixtureRequest, served: tuple[str, list[Message]], tmp_path: Path
) -> AsyncIterator[Agent]:
    """The same tools two ways: ``rwt mcp`` in front of the robot, and its own ``/mcp``."""
    opened = rwt_mcp(served[0], tmp_path) if request.param == "stdio" else rwt_serve_mcp(served[0])
    async with opened as started:
        yield started


async def test_rwt_mcp_drives_a_robot(served: tuple[str, list[Message]], agent: Agent) -> None:
    _, received = served
    with anyio.fail_after(30):  # every step is bounded; a hang fails here
        listed = (await agent.session.list_tools()).tools
        assert {tool.name for tool in listed} == TOOLS
        assert all(tool.input_schema["type"] == "object" for tool in listed)
        echo = next(tool for tool in listed if tool.name == "echo")
        assert f"MAX_ECHO_COUNT ({MAX_ECHO_COUNT})" in (echo.description or "")  # its bound
        await _graph(agent)
        await _topics(agent, received)
        await _services_and_parameters(agent)
        await _actions(agent)
        await _tf(agent)


async def _graph(agent: Agent) -> None:
    topics = (await agent.call("list_topics"))["topics"]
    assert {"name": "/battery", "type": "std_msgs/msg/String"} in topics
    assert "/lights" in (await agent.call("list_services"))["names"]
    assert "/robot" in (await agent.call("list_nodes"))["names"]
    assert "/fibonacci" in (await agent.call("list_actions"))["names"]
    assert "/robot:max_speed" in (await agent.call("list_parameters"))["names"]
    twist = await agent.call("type_definition", type="geometry_msgs/msg/Twist")
    schema = twist["json_schema"]
    assert schema["type"] == "object" and set(schema["properties"]) == {"linear", "angular"}
    vector = schema["properties"]["linear"]["$ref"].removeprefix("#/$defs/").replace("~1", "/")
    assert schema["$defs"][vector]["properties"]["x"] == {"type": "number"}
    unknown = await agent.result("type_definition", type="no_pkg/msg/Nothing")
    assert unknown.is_error


async def _topics(agent: Agent, received: list[Message]) -> None:
    echoed = await agent.result("echo", topic="/battery", count=1, timeout_s=5)
    assert not echoed.is_error
    texts = [block.text for block in echoed.content if isinstance(block, TextContent)]
    assert json.loads(texts[0]) == {
        "topic": "/battery",
        "type": "std_msgs/msg/String",
        "received": 1,
    }
    assert json.loads(texts[1]) == {"data": "87%"}

    scan = await agent.result("echo", topic="/scan_like", timeout_s=5)
    assert json.loads(scan.content[1].text)["data"] == "<float[1000]>"  # type: ignore[union-attr]

    quiet = await agent.result("echo", topic="/cmd", count=3, timeout_s=0.5)
    assert json.loads(quiet.content[0].text)["timed_out"] is True  # type: ignore[union-attr]

    image = await agent.result("echo", topic="/camera/image", timeout_s=5)
    shown = [block for block in image.content if isinstance(block, ImageContent)]
    assert len(shown) == 1 and shown[0].mime_type == "image/png"
    picture = Image.open(io.BytesIO(base64.b64decode(shown[0].data)))
    assert picture.size == (WIDTH, HEIGHT) and picture.getpixel((0, 0)) == (255, 0, 0)

    sent = await agent.call("publish", topic="/cmd", type="std_msgs/msg/String", msg={"data": "go"})
    assert sent["count"] == 1
    with anyio.fail_after(5):
        while {"data": "go"} not in received:
            await anyio.sleep(0.02)
    repeated = await agent.call(
        "publish_for",
        topic="/cmd",
        type="std_msgs/msg/String",
        msg={"data": "on"},
        rate_hz=20,
        duration_s=0.3,
        final_msg={"data": "off"},
    )
    assert repeated["count"] >= 1 and repeated["final_sent"] is True
    with anyio.fail_after(5):
        while not received or received[-1] != {"data": "off"}:
            await anyio.sleep(0.02)
    assert received.count({"data": "on"}) == repeated["count"]
    clash = await agent.result(
        "publish", topic="/battery", type="std_msgs/msg/Int32", msg={"data": 1}
    )
    assert clash.is_error  # the server's refusal of the advertisement, in its words
    assert "is established with type std_msgs/msg/String" in clash.content[0].text  # type: ignore[union-attr]
    too_long = await agent.result("echo", topic="/battery", timeout_s=1000)
    assert too_long.is_error and "timeout_s must be in (0, 60]" in too_long.content[0].text  # type: ignore[union-attr]
    too_fast = await agent.result(
        "publish_for", topic="/cmd", type="std_msgs/msg/String", msg={}, rate_hz=1e6, duration_s=1
    )
    assert too_fast.is_error and "rate_hz" in too_fast.content[0].text  # type: ignore[union-attr]


async def _services_and_parameters(agent: Agent) -> None:
    answer = await agent.call(
        "call_service", service="/lights", type="std_srvs/srv/SetBool", args={"data": True}
    )
    assert answer["values"]["success"] is True
    missing = await agent.result("call_service", service="/no_such_service", timeout_s=5)
    assert missing.is_error
    assert "/no_such_service" in missing.content[0].text  # type: ignore[union-attr]

    assert (await agent.call("get_parameter", name="/robot:max_speed"))["value"] == 1.5
    long = await agent.call("get_parameter", name="/robot:path")
    assert long["value"] == "<float[100]>"  # summarised as echo's messages
    written = await agent.call("set_parameter", name="/robot:max_speed", value=0.5)
    assert written["value"] == 0.5
    assert (await agent.call("get_parameter", name="/robot:max_speed"))["value"] == 0.5


async def _actions(agent: Agent) -> None:
    progress: list[tuple[float, str | None]] = []

    async def on_progress(value: float, total: float | None, message: str | None) -> None:
        progress.append((value, message))

    done = await agent.session.call_tool(
        "send_action_goal",
        {"action": "/fibonacci", "type": FIB, "goal": {"order": 5}, "timeout_s": 10},
        progress_callback=on_progress,
    )
    assert not done.is_error, done.content
    report = done.structured_content
    assert report is not None
    assert report["state"] == "succeeded" and report["status"] == 4
    assert report["result"] == {"sequence": [0, 1, 1, 2, 3, 5]}
    assert report["feedback_count"] == 4
    # the last feedback is always among the notifications, before the result
    assert progress[-1] == (4, json.dumps({"sequence": [0, 1, 1, 2, 3, 5]}))

    held = await agent.call(
        "send_action_goal", action="/fibonacci", type=FIB, goal={"order": HOLD_ORDER}, timeout_s=0.3
    )
    assert held["state"] == "running"
    status = await agent.call("action_goal_status", goal_id=held["goal_id"])
    assert status["state"] == "running"
    canceled = await agent.call(
        "cancel_action_goal", action="/fibonacci", goal_id=held["goal_id"], timeout_s=5
    )
    assert canceled["state"] == "canceled" and canceled["status"] == 5
    status = await agent.call("action_goal_status", goal_id=held["goal_id"])
    assert status["state"] == "canceled"
    assert (await agent.result("action_goal_status", goal_id="nope")).is_error


async def _tf(agent: Agent) -> None:
    found = await agent.call(
        "lookup_transform", target_frame="base_link", source_frame="camera", timeout_s=5
    )
    assert found["translation"] == pytest.approx({"x": 0.1, "y": 0.0, "z": 0.3})
    assert found["rotation"] == pytest.approx({"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0})
    lost = await agent.result(
        "lookup_transform", target_frame="base_link", source_frame="nowhere", timeout_s=1
    )
    assert lost.is_error and "nowhere" in lost.content[0].text  # type: ignore[union-attr]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


async def _clients(agent: Agent) -> set[str]:
    """The rosbridge clients the server lists as nodes (``/rwt_client_<n>``)."""
    nodes = (await agent.call("list_nodes"))["names"]
    return {node for node in nodes if node.startswith("/rwt_client_")}


async def test_one_connection_made_in_the_background_and_again_after_a_drop(
    tmp_path: Path,
) -> None:
    port = free_port()
    graph = robot_graph([])
    async with rwt_mcp(f"127.0.0.1:{port}", tmp_path) as agent:  # HOST:PORT, nothing there yet
        with anyio.fail_after(25):
            down = await agent.result("list_topics")
            assert down.is_error
            assert f"not connected to ws://127.0.0.1:{port}" in down.content[0].text  # type: ignore[union-attr]
            for _ in range(2):  # the robot comes up, goes away, and comes back
                async with anyio.create_task_group() as tg:
                    config = ServerConfig(host="127.0.0.1", port=port)
                    await tg.start(RosbridgeServer(graph, config).serve)
                    while (await agent.result("get_parameter", name="/robot:name")).is_error:
                        await anyio.sleep(0.1)  # (a listing's rate is lower: LISTING_CALLS_PER_S)
                    first = await _clients(agent)
                    assert not (await agent.result("echo", topic="/battery")).is_error
                    await agent.call("get_parameter", name="/robot:max_speed")
                    assert len(first) == 1 and await _clients(agent) == first
                    tg.cancel_scope.cancel()


def test_a_url_of_another_scheme_is_one_line_and_exit_code_2() -> None:
    result = invoke_rwt("mcp", "http://127.0.0.1:9090")
    assert result.exit_code == 2
    assert "unsupported URL scheme 'http'" in result.output
