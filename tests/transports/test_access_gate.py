"""Every refusal of the access rules goes through the one gate and its one log line.

``rwt_protocol.runtime.access.gate``: the three paths that once refused without it
(a Foxglove client's parameters, an MCP session's tools, WebRTC video tracks) now say
what they refused as every session does, ``event=access_denied client=... op=...
glob=...``, while each client is told in its own protocol's words.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_protocol.ratelog import EpisodeLog
from rwt_protocol.runtime import access
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.runtime.rules import ClientRules
from tests.foxglove.sansio import Client

pytestmark = pytest.mark.anyio


Denials = Callable[[], list[str]]


@pytest.fixture
def denials(caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch) -> Denials:
    """The gate's lines from here on (a fresh episode: another test's may be open)."""
    monkeypatch.setattr(access, "_episodes", EpisodeLog(access.logger))
    caplog.set_level(logging.WARNING, logger="rwt.session")
    return lambda: [
        r.getMessage() for r in caplog.records if r.getMessage().startswith("event=access_denied")
    ]


def test_a_foxglove_clients_parameter_is_refused_through_the_gate(denials: Denials) -> None:
    graph = Graph()
    graph.params.declare("/arm", {"x": 1})
    client = Client(graph, with_params=True, access=AccessPolicy(params=("/robot:*",)))
    client.send({"op": "getParameters", "parameterNames": ["/arm.x"]})
    errors = [op["message"] for op in client.take_ops("status") if op["level"] == 2]
    assert errors == ["getParameters: parameter /arm:x is not allowed"]  # Foxglove's words
    assert denials() == [
        "event=access_denied client=foxglove:test#1 op=getParameters glob=params_glob "
        "reason='param /arm:x is not allowed on this server'"
    ]


async def test_an_mcp_tool_call_is_refused_through_the_gate(denials: Denials) -> None:
    pytest.importorskip("mcp", reason="the MCP tests need the MCP SDK", exc_type=ImportError)
    from mcp.server.mcpserver.exceptions import ToolError  # noqa: PLC0415

    from rwt_mcp.session import McpSession  # noqa: PLC0415

    graph = Graph()
    rules = ClientRules(access=AccessPolicy(topics_sub=("/battery",)))
    session = McpSession(graph.port, "mcp:127.0.0.1:5000#3", config=rules)
    with pytest.raises(ToolError, match=r"topic /cmd: refused by --topics-sub-glob \[/battery\]"):
        await session.subscribe("/cmd", "std_msgs/msg/String", lambda _msg: None)
    subscription = await session.subscribe("/battery", "std_msgs/msg/String", lambda _msg: None)
    await subscription.unsubscribe()
    assert denials() == [
        "event=access_denied client=mcp:127.0.0.1:5000#3 op=subscribe glob=topics_sub_glob "
        "reason='topic /cmd is not allowed on this server'"
    ]


async def test_a_webrtc_video_track_is_refused_through_the_gate(denials: Denials) -> None:
    pytest.importorskip("aiortc", reason="the WebRTC tests need aiortc", exc_type=ImportError)
    from rwt_transports.webrtc.signalling import VideoRequest  # noqa: PLC0415
    from rwt_transports.webrtc.video import WebRtcVideo  # noqa: PLC0415

    graph = Graph()
    graph.create_publisher("/secret/image", "sensor_msgs/msg/Image")
    video = WebRtcVideo(graph, AccessPolicy(topics=("/camera/*",)))
    async with anyio.create_task_group() as tg:
        video.bind(tg)
        answer = video.binding(VideoRequest(("/secret/image",)), "webrtc:127.0.0.1:5000")
        video.bind(None)
    assert (answer.status, answer.text) == (403, "topic '/secret/image' is not allowed")  # type: ignore[union-attr]
    assert denials() == [
        "event=access_denied client=webrtc:127.0.0.1:5000 op=video glob=topics_glob "
        "reason='topic /secret/image is not allowed on this server'"
    ]
