"""ros-mcp-server (PyPI ``ros-mcp``), the MCP server AI agents drive robots with, against rwt.

The official MCP Python client (``mcp``, 2.x) starts the real ros-mcp 3.1.2 as an MCP
stdio server (from an environment of its own, ``tests.support.ros_mcp``: it holds mcp
below 2), points it at an rwt server with ``connect_to_robot`` and calls each
of its tools that concerns a robot on a small graph: a latched topic, a
subscription, a service, an action whose long goals run until canceled, and a
node's parameters. Each answer is checked for what ros-mcp says it found
(docs/agents.md). ros-mcp opens one connection per tool call, so its
``get_parameters`` needs the node's own parameter services, ``get_action_status``
the action's status topic, and ``cancel_action_goal`` a goal table shared by the
connections (D35).
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import anyio
import pytest

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_graph.actions import GoalCanceledError, GoalContext
from tests.support.ros_mcp import ros_mcp_python

pytest.importorskip("mcp", reason="the MCP client is not installed (pip install 'rwt[test]')")

from mcp import ClientSession, StdioServerParameters
from mcp.client.stdio import stdio_client

ROS_MCP_PYTHON, _why = ros_mcp_python()  # its own environment: it holds mcp below 2 (D52)
if ROS_MCP_PYTHON is None:
    pytest.skip(f"ros-mcp 3.1.2 cannot run here: {_why}", allow_module_level=True)

pytestmark = pytest.mark.anyio

FIB = "example_interfaces/action/Fibonacci"
HOLD_ORDER = 100  # a goal of this order runs until canceled
#: Tools that concern no robot: images saved by earlier calls, the robot
#: specifications bundled with ros-mcp, pinging hosts of a list.
NOT_ROBOT_TOOLS = {
    "view_saved_image",
    "get_verified_robot_spec",
    "get_verified_robots_list",
    "ping_robots",
}

Message = dict[str, Any]


def robot_graph(received: list[Message]) -> Graph:
    """A small robot: a latched battery topic, /cmd, /lights, /fibonacci and parameters."""
    graph = Graph()
    graph.params.declare("/robot", {"max_speed": 1.5, "name": "r2", "scratch": 7})
    battery = graph.create_publisher("/battery", "std_msgs/msg/String", latch=True, node="/robot")
    battery.publish({"data": "87%"})
    graph.create_subscription("/cmd", received.append, "std_msgs/msg/String", node="/robot")
    graph.create_service(
        "/lights", "std_srvs/srv/SetBool", lambda req: {"success": req["data"]}, node="/robot"
    )

    async def fibonacci(goal: Message, context: GoalContext) -> Message:
        sequence = [0, 1]
        if goal["order"] >= HOLD_ORDER:
            while not context.cancel_requested:
                await anyio.sleep(0.01)
            raise GoalCanceledError
        for _ in range(1, goal["order"]):
            sequence.append(sequence[-1] + sequence[-2])
            context.publish_feedback({"sequence": sequence})
        return {"sequence": sequence}

    graph.create_action_server("/fibonacci", FIB, fibonacci, node="/robot")
    return graph


@pytest.fixture
async def served(tmp_path: Path) -> AsyncIterator[tuple[int, list[Message]]]:
    """rwt serving the robot on a free port: ``(port, messages /cmd received)``."""
    received: list[Message] = []
    server = RosbridgeServer(robot_graph(received), ServerConfig(host="127.0.0.1", port=0))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield int(url.rsplit(":", 1)[1]), received
        tg.cancel_scope.cancel()


class Agent:
    """An MCP client session with ros-mcp: ``call`` a tool, get its JSON answer."""

    def __init__(self, session: ClientSession) -> None:
        self.session = session

    async def call(self, tool: str, **arguments: object) -> Message:
        result = await self.session.call_tool(tool, arguments)
        assert not result.is_error, result.content
        answer = json.loads(result.content[0].text)  # type: ignore[union-attr]
        assert isinstance(answer, dict)
        return answer


@pytest.fixture
async def agent(tmp_path: Path) -> AsyncIterator[Agent]:
    """ros-mcp 3.1.2 started as an MCP stdio server by the official client."""
    params = StdioServerParameters(
        command=str(ROS_MCP_PYTHON), args=["-m", "ros_mcp.main"], cwd=str(tmp_path)
    )
    with (tmp_path / "ros-mcp.log").open("w") as errlog:
        async with (
            stdio_client(params, errlog=errlog) as (read, write),
            ClientSession(read, write) as session,
        ):
            await session.initialize()
            yield Agent(session)


async def test_ros_mcp_drives_a_robot_served_by_rwt(
    served: tuple[int, list[Message]], agent: Agent
) -> None:
    port, received = served
    with anyio.fail_after(60):  # every step is bounded; a hang fails here
        tools = {tool.name for tool in (await agent.session.list_tools()).tools}
        assert len(tools) == 31 and "get_action_status" in tools  # ros-mcp 3.1.2's tools

        connected = await agent.call("connect_to_robot", ip="127.0.0.1", port=port)
        assert connected["message"] == f"WebSocket IP set to 127.0.0.1:{port}"
        assert (await agent.call("detect_ros_version"))["version"] == "2"

        await _topics(agent, received)
        await _services_and_nodes(agent)
        await _parameters(agent)
        await _actions(agent)
        called = {"connect_to_robot", "detect_ros_version", *_CALLED}
        assert tools - called == NOT_ROBOT_TOOLS


_CALLED = {
    "get_topics",
    "get_topic_type",
    "get_topic_details",
    "get_message_details",
    "subscribe_once",
    "subscribe_for_duration",
    "publish_once",
    "publish_for_durations",
    "get_services",
    "get_service_type",
    "get_service_details",
    "call_service",
    "get_nodes",
    "get_node_details",
    "get_parameters",
    "get_parameter",
    "set_parameter",
    "has_parameter",
    "delete_parameter",
    "get_parameter_details",
    "get_actions",
    "get_action_details",
    "send_action_goal",
    "get_action_status",
    "cancel_action_goal",
}


async def _topics(agent: Agent, received: list[Message]) -> None:
    topics = await agent.call("get_topics")
    assert "/battery" in topics["topics"] and "/cmd" in topics["topics"]
    assert (await agent.call("get_topic_type", topic="/battery"))["type"] == "std_msgs/msg/String"
    details = await agent.call("get_topic_details", topic="/battery")
    assert details["publishers"] == ["/robot"]
    fields = await agent.call("get_message_details", message_type="std_msgs/msg/String")
    assert fields["structure"]["std_msgs/String"]["fields"] == {"data": "string"}
    once = await agent.call("subscribe_once", topic="/battery", msg_type="std_msgs/msg/String")
    assert once["msg"] == {"data": "87%"}
    during = await agent.call(
        "subscribe_for_duration", topic="/battery", msg_type="std_msgs/msg/String", duration=0.5
    )
    assert during["collected_count"] == 1
    await agent.call(
        "publish_once", topic="/cmd", msg_type="std_msgs/msg/String", msg={"data": "go"}
    )
    await agent.call(
        "publish_for_durations",
        topic="/cmd",
        msg_type="std_msgs/msg/String",
        messages=[{"data": "left"}],
        durations=[0.2],
    )
    with anyio.fail_after(5):
        while len(received) < 2:
            await anyio.sleep(0.01)
    assert [m["data"] for m in received][:2] == ["go", "left"]


async def _services_and_nodes(agent: Agent) -> None:
    services = (await agent.call("get_services"))["services"]
    assert "/lights" in services and "/robot/list_parameters" in services
    assert (await agent.call("get_service_type", service="/lights"))["type"] == (
        "std_srvs/srv/SetBool"
    )
    details = await agent.call("get_service_details", service="/lights")
    assert details["request"]["fields"] == {"data": "boolean"}  # rosapi's spelling
    called = await agent.call(
        "call_service",
        service_name="/lights",
        service_type="std_srvs/srv/SetBool",
        request={"data": True},
    )
    assert called["success"] is True and called["result"]["success"] is True
    assert "/robot" in (await agent.call("get_nodes"))["nodes"]
    node = await agent.call("get_node_details", node="/robot")
    assert (node["publishers"], node["subscribers"]) == (["/battery"], ["/cmd"])
    assert "/lights" in node["services"] and "/robot/get_parameters" in node["services"]


async def _parameters(agent: Agent) -> None:
    listed = await agent.call("get_parameters", node_name="robot")
    assert sorted(listed["parameters"]) == ["/robot:max_speed", "/robot:name", "/robot:scratch"]
    value = await agent.call("get_parameter", name="/robot:max_speed")
    assert (value["value"], value["successful"]) == ("1.5", True)
    assert (await agent.call("set_parameter", name="/robot:max_speed", value="2.5"))["successful"]
    assert (await agent.call("get_parameter", name="/robot:max_speed"))["value"] == "2.5"
    assert (await agent.call("has_parameter", name="/robot:name"))["exists"] is True
    details = await agent.call("get_parameter_details", name="/robot:name")
    assert (details["value"], details["type"], details["exists"]) == ('"r2"', "string", True)
    assert (await agent.call("delete_parameter", name="/robot:scratch"))["successful"]
    assert (await agent.call("has_parameter", name="/robot:scratch"))["exists"] is False


async def _actions(agent: Agent) -> None:
    assert "/fibonacci" in (await agent.call("get_actions"))["actions"]
    details = await agent.call("get_action_details", action="/fibonacci", action_type=FIB)
    assert details["goal"]["fields"] == {"order": "int32"}
    done = await agent.call(
        "send_action_goal", action_name="/fibonacci", action_type=FIB, goal={"order": 5}
    )
    assert (done["success"], done["status"], done["result"]) == (
        True,
        4,
        {"sequence": [0, 1, 1, 2, 3, 5]},
    )
    # a long goal: ros-mcp stops waiting, the goal runs on; another call cancels it
    held = await agent.call(
        "send_action_goal",
        action_name="/fibonacci",
        action_type=FIB,
        goal={"order": HOLD_ORDER},
        timeout=0.5,
    )
    assert held["success"] is False and "timed out" in held["error"]
    status = await agent.call("get_action_status", action_name="/fibonacci")
    assert [g["status_text"] for g in status["active_goals"]] == [
        "STATUS_SUCCEEDED",
        "STATUS_EXECUTING",
    ]
    canceled = await agent.call(
        "cancel_action_goal", action_name="/fibonacci", goal_id=held["goal_id"]
    )
    assert canceled["success"] is True
    with anyio.fail_after(10):
        while True:
            status = await agent.call("get_action_status", action_name="/fibonacci")
            texts = [g["status_text"] for g in status["active_goals"]]
            if texts[-1] == "STATUS_CANCELED":
                break
            assert texts[-1] in {"STATUS_EXECUTING", "STATUS_CANCELING"}
    assert texts == ["STATUS_SUCCEEDED", "STATUS_CANCELED"]
