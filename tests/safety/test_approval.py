"""A person's approval before an MCP agent acts, with the official SDK's client (2.x).

The example's ``/cmd_vel`` has ``approval = true``. The client's elicitation handler is
the person: on 2026-07-28 the server answers the tool call with an input-required
result and the client calls again with the answer (multi round-trip requests); a
2025-era client is asked by ``elicitation/create`` while the call waits. A decline,
or no answer within ``approval_timeout_s``, publishes nothing and the tool result
says so; a client that can ask no one gets a tool error saying why. ``rwt mcp URL
--safety FILE`` asks the same (docs/agents.md, D69). Every outcome is in the audit.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import pytest

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp import Client, StdioServerParameters
from mcp.types import CallToolResult, ElicitRequestParams, ElicitResult

from rwt import RosbridgeServer, ServerConfig
from rwt_transports.http.mcp_options import McpOptions
from tests.safety.example import EXAMPLE, STOP, Robot, example_file, twist
from tests.support.cli import ENV, RWT

pytestmark = pytest.mark.anyio

MODERN = "2026-07-28"
LEGACY = "legacy"
DRIVE = {"topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist", "msg": twist(0.2)}
RESET = """
[[service]]
name = "/reset"
approval = true
"""
QUICK = "approval_timeout_s = 1\n"  # a person who does not answer in time


class Person:
    """The client's elicitation handler: answers ``answer`` (or nothing for ``delay_s``)."""

    def __init__(self, answer: str, delay_s: float = 0.0) -> None:
        self.answer = answer
        self.delay_s = delay_s
        self.asked: list[str] = []

    async def __call__(self, context: Any, params: ElicitRequestParams) -> ElicitResult:
        self.asked.append(params.message)
        await anyio.sleep(self.delay_s)
        if self.answer == "accept":
            return ElicitResult(action="accept", content={"approve": True})
        return ElicitResult(action=self.answer)  # type: ignore[arg-type]


@asynccontextmanager
async def served(text: str = EXAMPLE) -> AsyncIterator[tuple[Robot, str, list[str]]]:
    """``(robot, ws url, reset calls)``: the rules of ``text``, ``--mcp``, a ``/reset`` service."""
    robot = Robot.make(text)
    resets: list[str] = []
    robot.graph.create_service(
        "/reset", "std_srvs/srv/Trigger", lambda req: resets.append("reset") or {"success": True}
    )
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions())
    server = RosbridgeServer(robot.graph, config)
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield robot, url, resets
        server.stop()


def _mcp(url: str) -> str:
    return "http://" + url.split("://", 1)[1] + "/mcp"


async def _publish(url: str, mode: str, person: Person | None) -> CallToolResult:
    with anyio.fail_after(60):
        async with Client(_mcp(url), mode=mode, elicitation_callback=person) as client:
            assert (client.protocol_version == MODERN) == (mode == MODERN)
            return await client.call_tool("publish", DRIVE)


def _text(result: CallToolResult) -> str:
    return " ".join(getattr(block, "text", "") for block in result.content)


def _kinds(robot: Robot) -> list[str]:
    assert robot.graph.safety is not None
    return [event.kind for event in robot.graph.safety.audit.last()]


@pytest.mark.parametrize("mode", [MODERN, LEGACY])
async def test_a_person_who_declines_stops_the_publish(mode: str) -> None:
    async with served() as (robot, url, _):
        person = Person("decline")
        result = await _publish(url, mode, person)
        assert result.is_error
        assert "the person did not approve it: nothing was done" in _text(result)
        assert len(person.asked) == 1
        assert "publish on /cmd_vel" in person.asked[0]
        assert '"x":0.2' in person.asked[0]
        assert robot.cmd_vel == []
        assert _kinds(robot) == ["approval_declined"]


@pytest.mark.parametrize("mode", [MODERN, LEGACY])
async def test_a_person_who_accepts_lets_it_through(mode: str) -> None:
    async with served() as (robot, url, _):
        result = await _publish(url, mode, Person("accept"))
        assert not result.is_error, _text(result)
        await robot.wait_for(lambda: robot.cmd_vel, "the command")
        assert robot.twists[0] == twist(0.2)
        await robot.wait_for(lambda: len(robot.cmd_vel) == 2, "the dead-man's stop")
        assert robot.twists[1] == STOP  # the agent commands no more: the dead-man stops it
        assert _kinds(robot)[0] == "approval_given"


@pytest.mark.parametrize("mode", [MODERN, LEGACY])
async def test_no_answer_in_time_publishes_nothing(mode: str) -> None:
    async with served(QUICK + EXAMPLE) as (robot, url, _):
        result = await _publish(url, mode, Person("accept", delay_s=2.0))
        assert result.is_error
        assert "no answer from the person within 1 s: nothing was done" in _text(result)
        assert robot.cmd_vel == []
        assert _kinds(robot) == ["approval_timeout"]


@pytest.mark.parametrize("mode", [MODERN, LEGACY])
async def test_a_client_that_cannot_ask_gets_a_tool_error(mode: str) -> None:
    async with served() as (robot, url, _):
        result = await _publish(url, mode, None)
        assert result.is_error
        assert "needs a person's approval, and this MCP client offers no way to ask" in _text(
            result
        )
        assert robot.cmd_vel == []


async def test_a_service_call_waits_for_the_person() -> None:
    async with served(EXAMPLE + RESET) as (_, url, resets):
        for answer in ("decline", "accept"):
            async with Client(_mcp(url), mode=MODERN, elicitation_callback=Person(answer)) as c:
                result = await c.call_tool("call_service", {"service": "/reset"})
            assert result.is_error == (answer == "decline"), _text(result)
        assert resets == ["reset"]


async def test_the_robot_app_does_not_drive_a_topic_that_needs_approval() -> None:
    async with served() as (_, url, _), Client(_mcp(url), mode=MODERN) as client:
        result = await client.call_tool("robot_app", {})
    settings = result.structured_content or {}
    assert settings["teleop"] is False
    assert "needs a person's approval" in settings["teleop_refused"]


@pytest.mark.parametrize("mode", [MODERN, LEGACY])
async def test_rwt_mcp_url_asks_the_same(tmp_path: Path, mode: str) -> None:
    rules = example_file(tmp_path)
    async with served() as (robot, url, _):
        args = [*RWT[1:], "mcp", url, "--safety", str(rules)]
        stdio = StdioServerParameters(command=RWT[0], args=args, env=dict(ENV))
        for answer in ("decline", "accept"):
            with anyio.fail_after(60):
                async with Client(stdio, mode=mode, elicitation_callback=Person(answer)) as c:
                    result = await c.call_tool("publish", DRIVE)
            assert result.is_error == (answer == "decline"), _text(result)
        await robot.wait_for(lambda: robot.cmd_vel, "the accepted command")
        assert robot.twists[0] == twist(0.2)


async def test_a_goal_that_needs_approval_is_asked_for_not_made_a_task() -> None:
    """A client that takes tasks gets no task for such a goal: the person is asked first."""
    from tests.agents.test_mcp_revisions import Tasks  # noqa: PLC0415 (the Tasks extension)

    goals: list[int] = []
    async with served(EXAMPLE + '\n[[action]]\nname = "/fibonacci"\n') as (robot, url, _):

        async def fibonacci(goal: dict[str, Any], context: Any) -> dict[str, Any]:
            goals.append(goal["order"])
            return {"sequence": [0, 1]}

        robot.graph.create_action_server(
            "/fibonacci", "example_interfaces/action/Fibonacci", fibonacci
        )
        goal = {"action": "/fibonacci", "type": "example_interfaces/action/Fibonacci"}
        for answer, order in (("decline", 1), ("accept", 2)):
            person = Person(answer)
            async with Client(
                _mcp(url), mode=MODERN, extensions=[Tasks()], elicitation_callback=person
            ) as client:
                result = await client.call_tool(
                    "send_action_goal", {**goal, "goal": {"order": order}}
                )
            assert isinstance(result, CallToolResult)
            assert result.is_error == (answer == "decline"), _text(result)
            assert "send a goal to /fibonacci" in person.asked[0]
        assert goals == [2]


LONG_DEADMAN = """\
[[topic]]
name = "/cmd_vel"
type = "geometry_msgs/msg/Twist"
on_violation = "clamp"
deadman_s = 60
[topic.bounds]
"linear.x" = [-0.5, 0.5]
[topic.stop]
linear = { x = 0.0, y = 0.0, z = 0.0 }
angular = { x = 0.0, y = 0.0, z = 0.0 }
"""


async def test_a_2025_session_that_ends_gets_the_stop_and_the_agent_is_told_of_clamps() -> None:
    """No approval here: the clamp in the tool's result, the stop when the session ends.

    With ``deadman_s`` 60 the stop within the hang guard can only be the session's end.
    """
    async with served(LONG_DEADMAN) as (robot, url, _):
        async with Client(_mcp(url), mode=LEGACY) as client:
            result = await client.call_tool("publish", {**DRIVE, "msg": twist(2.0)})
            assert not result.is_error, _text(result)
            assert (result.structured_content or {})["safety"] == [
                "/cmd_vel: linear.x 2 clamped to 0.5 (bound [-0.5, 0.5])"
            ]
            await robot.wait_for(lambda: robot.cmd_vel, "the command")
        await robot.wait_for(lambda: len(robot.cmd_vel) == 2, "the stop at the session's end")
    assert robot.twists == [twist(0.5), STOP]
