"""The robot app (MCP Apps) as the official SDK's clients of both revisions see it.

``robot_app`` names ``ui://rwt/robot`` in its ``_meta.ui``; the resource is listed
first and read as HTML of the ``mcp-app`` profile with the origins its frame may
reach; the tool answers the app's settings: where the camera's video is (WebRTC on
the server's port, MJPEG of the video server), a video token when the server has
an auth secret, and whether the pad may drive, under read-only mode and the access
rules (docs/mcp.md, "The robot app"). tests/browser/test_mcp_app.py renders it.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from typing import Any

import anyio
import pytest

from rwt import RosbridgeServer, ServerConfig
from rwt_protocol.ratelog import EpisodeLog
from rwt_protocol.runtime import access as access_gate
from rwt_protocol.runtime.access import AccessPolicy, parse_split_glob
from rwt_protocol.server.session import SessionConfig

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp.server.mcpserver.exceptions import ToolError
from mcp.shared.exceptions import MCPError

from rwt_mcp.app import APP_MIME, APP_URI, AppSite
from rwt_mcp.cli import stdio_site
from rwt_mcp.link import RobotLink
from rwt_mcp.tools import RobotTools
from rwt_protocol.names import MAX_NAME_LENGTH
from rwt_transports.http.mcp_options import McpOptions
from rwt_transports.server import rosauth_authenticator
from rwt_video import VideoTokens, install_token_service
from tests.agents.test_mcp_revisions import AUTO, connect, robot

pytestmark = pytest.mark.anyio

ARGS = {"camera": "/camera/image", "cmd_vel": "/cmd_vel"}
SECRET = "s3cret-s3cret-s3cret"


@pytest.fixture
async def serve() -> AsyncIterator[Any]:
    """Serve the robot with ``mcp`` options (and ``fields`` of its config); its ws URL."""
    async with anyio.create_task_group() as tg:

        async def start(mcp: McpOptions, tokens: VideoTokens | None = None, **fields: Any) -> str:
            graph = robot([])
            extra: dict[str, Any] = {}
            if tokens is not None:  # as --auth-secret-file does
                install_token_service(graph, tokens)
                extra["authenticator"] = rosauth_authenticator(SECRET, graph.clock)
            config = ServerConfig(host="127.0.0.1", port=0, mcp=mcp, **fields)
            return str(await tg.start(RosbridgeServer(graph, config, **extra).serve))

        yield start
        tg.cancel_scope.cancel()


@pytest.mark.parametrize("mode", [AUTO, "legacy"])
@pytest.mark.parametrize("front", ["http", "stdio"])
async def test_the_tool_names_the_app_and_the_app_is_a_listed_resource(
    serve: Any, front: str, mode: str
) -> None:
    url = await serve(McpOptions(video_port=8089))
    http = "http://" + url.split("://", 1)[1]
    with anyio.fail_after(60):
        async with connect(url, front, mode) as client:
            tools = {tool.name: tool for tool in (await client.list_tools()).tools}
            assert tools["robot_app"].meta == {"ui": {"resourceUri": APP_URI}}
            assert tools["robot_app"].annotations.read_only_hint is True  # type: ignore[union-attr]
            listed = (await client.list_resources()).resources
            assert (str(listed[0].uri), listed[0].mime_type) == (APP_URI, APP_MIME)
            read = (await client.read_resource(APP_URI)).contents[0]
            assert read.mime_type == APP_MIME
            assert read.text.startswith("<!doctype html>")  # type: ignore[union-attr]
            assert '"ui/initialize"' in read.text  # type: ignore[union-attr]
            settings = (await client.call_tool("robot_app", ARGS)).structured_content
    assert settings is not None
    assert settings["teleop"] is True and settings["cmd_vel"] == "/cmd_vel"
    assert settings["token"] is None  # no auth secret: no token
    if front == "http":  # the server says where its video is, and what the frame may reach
        assert settings["webrtc_url"] is None  # it answers no WebRTC offers (no --webrtc)
        assert (
            settings["mjpeg_url"] == "http://127.0.0.1:8089/stream?topic=/camera/image&type=mjpeg"
        )
        assert read.meta == {
            "ui": {"csp": {"connectDomains": [http], "resourceDomains": ["http://127.0.0.1:8089"]}}
        }
    else:  # rwt mcp URL knows the server's port only: WebRTC is tried there
        assert settings["webrtc_url"] == f"{http}/webrtc?video=/camera/image"
        assert settings["mjpeg_url"] is None
        assert read.meta == {"ui": {"csp": {"connectDomains": [http], "resourceDomains": []}}}


async def test_with_an_auth_secret_the_app_gets_a_video_token(serve: Any) -> None:
    tokens = VideoTokens()
    mcp = McpOptions(bearer_token=tokens.valid, video_port=8089)
    url = await serve(mcp, tokens=tokens)
    bearer = tokens.issue()  # what an authenticated client asked /rwt/video_token for
    async with connect_with_token(url, bearer) as client:
        settings = (await client.call_tool("robot_app", ARGS)).structured_content
    assert settings is not None
    token = settings["token"]
    assert isinstance(token, str) and tokens.valid(token)
    assert settings["mjpeg_url"].endswith(f"&token={token}")


def connect_with_token(url: str, token: str) -> Any:
    """A 2026-07-28 client of ``/mcp`` sending ``Authorization: Bearer token``."""
    import httpx2  # noqa: PLC0415 (the SDK's HTTP client)
    from mcp import Client  # noqa: PLC0415
    from mcp.client.streamable_http import streamable_http_client  # noqa: PLC0415

    endpoint = "http://" + url.split("://", 1)[1] + "/mcp"
    http = httpx2.AsyncClient(headers={"Authorization": f"Bearer {token}"})
    return Client(streamable_http_client(endpoint, http_client=http), mode=AUTO)


async def test_read_only_mode_and_the_access_rules_turn_the_pad_off_saying_why(
    serve: Any, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the gate logs one line per episode of refusals in the process: a new episode here,
    # not one another test of this process began
    monkeypatch.setattr(access_gate, "_episodes", EpisodeLog(access_gate.logger))
    url = await serve(McpOptions(read_only=True))
    async with connect(url, "http", AUTO) as client:
        settings = (await client.call_tool("robot_app", ARGS)).structured_content
    assert settings is not None
    assert settings["teleop"] is False
    assert settings["teleop_refused"] == "the MCP server is read-only"

    access = AccessPolicy(topics_pub=parse_split_glob("['/robot/*']"))
    guarded = await serve(McpOptions(), session=SessionConfig(access=access))
    caplog.set_level(logging.INFO, "rwt")
    async with connect(guarded, "http", AUTO) as client:
        settings = (await client.call_tool("robot_app", ARGS)).structured_content
        wheels = {**ARGS, "cmd_vel": "/robot/cmd_vel"}
        allowed = (await client.call_tool("robot_app", wheels)).structured_content
        refused = await client.call_tool("robot_app", {**ARGS, "max_linear": 50})
    assert settings is not None and allowed is not None
    assert settings["teleop"] is False
    assert settings["teleop_refused"] == "cmd_vel /cmd_vel: refused by --topics-pub-glob [/robot/*]"
    assert allowed["teleop"] is True
    denied = [r.getMessage() for r in caplog.records]
    denied = [line for line in denied if line.startswith("event=access_denied")]
    assert len(denied) == 1 and "op=robot_app" in denied[0], denied  # logged once, by the gate
    assert refused.is_error
    assert "max_linear must be in (0, 10]" in refused.content[0].text  # type: ignore[union-attr]


@pytest.mark.parametrize(
    ("field", "value", "said"),
    [
        ("cmd_vel", "a b", "cmd_vel: not a topic name"),
        ("camera", "/" + "x" * MAX_NAME_LENGTH, "camera: not a topic name: name longer than"),
        ("max_linear", -1, "max_linear must be in (0, 10]"),
    ],
    ids=["space", "long", "negative"],
)
async def test_hostile_arguments_are_tool_errors_and_the_server_serves_on(
    serve: Any, field: str, value: object, said: str
) -> None:
    url = await serve(McpOptions(video_port=8089))
    async with connect(url, "http", AUTO) as client:
        refused = await client.call_tool("robot_app", {**ARGS, field: value})
        assert refused.is_error
        assert said in refused.content[0].text  # type: ignore[union-attr]
        with pytest.raises(MCPError, match="an integer does not fit in 64 bits"):
            await client.call_tool("robot_app", {**ARGS, "max_angular": 10**400})
        settings = (await client.call_tool("robot_app", ARGS)).structured_content
    assert settings is not None and settings["teleop"] is True


async def test_a_lone_surrogate_in_a_name_is_a_tool_error() -> None:
    """JSON may carry one (``"\\ud800"``); it never reaches a URL the app would load."""
    tools = RobotTools(RobotLink("ws://127.0.0.1:1"))
    with pytest.raises(ToolError, match="camera: not a topic name"):
        await tools.robot_app(camera="/cam\ud800era")


def test_rwt_mcp_looks_for_webrtc_on_the_servers_port() -> None:
    assert stdio_site("ws://robot.local:9090") == AppSite(base="http://robot.local:9090")
    assert stdio_site("wss://robot.local/") == AppSite(base="https://robot.local")
    assert stdio_site("tcp://robot.local:9091") == AppSite()
