"""``rwt serve --mcp``: each MCP session is a session of the server's runtime on the graph.

The official MCP client against a robot on a free port, and a rosbridge client
beside it seeing what the MCP session holds in the graph: what the tools hold is
the session's, and leaves the graph when the session ends; every name the tools
touch passes the server's one access gate, the agent's and their own (the TF
republisher's service); the server answers each refusal as a tool error naming
the rule, and logs it once.
"""

from __future__ import annotations

import logging
from typing import Any

import anyio
import pytest

from rwt import RosbridgeServer, ServerConfig
from rwt_client import Ros
from rwt_protocol.ratelog import EpisodeLog
from rwt_protocol.runtime import access as access_gate
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from rwt_transports.http.mcp_options import McpOptions
from tests.agents.test_mcp_safety import WRITES, _text
from tests.agents.test_rwt_mcp import Message, robot_graph, rwt_serve_mcp

pytestmark = pytest.mark.anyio


async def _publishers(url: str, topic: str) -> list[str]:
    """The nodes publishing ``topic``, as a rosbridge client asks rosapi."""
    async with Ros(url) as ros:
        answer = await ros.call_service("/rosapi/publishers", {"topic": topic})
    assert isinstance(answer, dict)
    return list(answer["publishers"])


async def test_what_an_mcp_session_held_leaves_the_graph_with_it() -> None:
    received: list[Message] = []
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions())
    server = RosbridgeServer(robot_graph(received), config)
    with anyio.fail_after(60):
        async with anyio.create_task_group() as tg:
            url = await tg.start(server.serve)
            before = await _publishers(url, "/cmd")
            async with rwt_serve_mcp(url) as agent:
                assert not (await agent.result("publish", **WRITES["publish"])).is_error
                assert received == [{"data": "go"}]
                during = await _publishers(url, "/cmd")
                assert len(during) == len(before) + 1  # the session's publisher of /cmd
            # the agent closed its session (DELETE): the server released what it held
            with anyio.fail_after(10):
                while len(await _publishers(url, "/cmd")) != len(before):
                    await anyio.sleep(0.05)
            tg.cancel_scope.cancel()


async def test_the_tools_own_calls_pass_the_access_gate(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    # lookup_transform calls the TF republisher's service: --services-glob holds it too
    monkeypatch.setattr(access_gate, "_episodes", EpisodeLog(access_gate.logger))
    caplog.set_level(logging.INFO, logger="rwt.session")
    access = AccessPolicy(services=("/lights",))
    config = ServerConfig(
        host="127.0.0.1", port=0, mcp=McpOptions(), session=SessionConfig(access=access)
    )
    server = RosbridgeServer(robot_graph([]), config)
    with anyio.fail_after(60):
        async with anyio.create_task_group() as tg:
            url = await tg.start(server.serve)
            async with rwt_serve_mcp(url) as agent:
                refused = await agent.result(
                    "lookup_transform", target_frame="base_link", source_frame="camera"
                )
                assert refused.is_error
                assert "service /republish_tfs: refused by --services-glob [/lights]" in _text(
                    refused
                )
                answered: Any = await agent.call(
                    "call_service", service="/lights", type="std_srvs/srv/SetBool"
                )
                assert answered["service"] == "/lights"
            tg.cancel_scope.cancel()
    denied = [r.getMessage() for r in caplog.records]
    denied = [line for line in denied if line.startswith("event=access_denied")]
    assert len(denied) == 1, denied  # once, by the one gate, with what the session asked
    assert "op=call_service glob=services_glob" in denied[0]
    assert denied[0].startswith("event=access_denied client=mcp:127.0.0.1:")


async def test_a_cancel_after_its_goal_ended_reports_the_end() -> None:
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions())
    server = RosbridgeServer(robot_graph([]), config)
    with anyio.fail_after(60):
        async with anyio.create_task_group() as tg:
            url = await tg.start(server.serve)
            async with rwt_serve_mcp(url) as agent:
                done = await agent.call("send_action_goal", **WRITES["send_action_goal"])
                assert done["state"] == "succeeded"
                again = await agent.call(
                    "cancel_action_goal", action="/fibonacci", goal_id=done["goal_id"]
                )
                assert again["state"] == "succeeded"  # it had ended: said, not an error
                unknown = await agent.result(
                    "cancel_action_goal", action="/fibonacci", goal_id="no-such-goal"
                )
                assert unknown.is_error and "no-such-goal" in _text(unknown)
            tg.cancel_scope.cancel()


async def test_a_name_rosbridge_refuses_is_refused_to_an_agent_too() -> None:
    received: list[Message] = []
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions())
    server = RosbridgeServer(robot_graph(received), config)
    with anyio.fail_after(60):
        async with anyio.create_task_group() as tg:
            url = await tg.start(server.serve)
            async with rwt_serve_mcp(url) as agent:
                bad = {**WRITES["publish"], "topic": "/robot/cmd/0"}  # a token from a digit
                refused = await agent.result("publish", **bad)
                assert refused.is_error
                assert "invalid name '/robot/cmd/0'" in _text(refused)
                async with Ros(url) as ros:  # what a rosbridge client learns of the graph
                    topics = await ros.call_service("/rosapi/topics", {})
                assert isinstance(topics, dict)
                assert "/robot/cmd/0" not in topics["topics"]
                assert not (await agent.result("publish", **WRITES["publish"])).is_error
                assert received == [{"data": "go"}]
            tg.cancel_scope.cancel()
