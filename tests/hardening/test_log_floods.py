"""What a client can repeat at will writes the log once per episode (docs/limits.md, logs).

Before, each of these wrote a line (a failing service: a whole traceback) per
request, so one client could fill the server's disk at its own rate: a service
whose handler raises, a refused ``auth``, an op the access rules deny, and video
streams started and stopped (or falling back to mjpeg) per HTTP request. After
1,000 of them (300 video streams: each is a whole HTTP request) the log holds a
handful of lines, and another client is served.
"""

from __future__ import annotations

import json
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import httpx
import pytest

from rwt_graph import ratelog
from rwt_graph.graph import Graph
from rwt_protocol import ratelog as core_ratelog
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server import gates
from rwt_protocol.server.session import SessionConfig
from rwt_transports import rosauth
from rwt_transports.server import ServerConfig, rosauth_authenticator
from rwt_video import VideoConfig, serve_video
from tests.support.clients import TRANSPORTS, Client, is_op, running_server

pytestmark = pytest.mark.anyio

FLOOD = 1000
VIDEO_FLOOD = 300  # a line each would be 20 times the bound asserted (3 x MAX_LINES)
MAX_LINES = 5  # the first line of an episode, and a summary if the clock passes 10 s
BROKEN = "/broken_in_log_floods"
"""A name no other test's service has: episodes are per server process and keyed by
the service, so another test's failing ``/broken`` within 10 s would have opened
this one's episode already, and its first line would not come."""
TIMEOUT_S = 120


def rwt_lines(caplog: pytest.LogCaptureFixture, level: int = logging.WARNING) -> list[str]:
    return [
        r.getMessage()[:200]
        for r in caplog.records
        if r.name.startswith("rwt") and r.levelno >= level
    ]


async def served(client: Client, tag: str) -> None:
    await client.send({"op": "call_service", "service": "/rosapi/nodes", "id": tag})
    assert (await client.expect(is_op("service_response", id=tag)))["result"] is True


def broken_robot() -> Graph:
    graph = Graph()

    def broken(request: dict[str, object]) -> dict[str, object]:
        raise ValueError("a bug in the robot's handler")

    graph.create_service(BROKEN, "std_srvs/srv/Trigger", broken)
    return graph


async def test_a_service_that_raises_logs_one_traceback_per_episode(
    caplog: pytest.LogCaptureFixture,
) -> None:
    with anyio.fail_after(TIMEOUT_S):
        async with running_server(graph=broken_robot()) as harness:
            client = await harness.connect("ws")
            other = await harness.connect("memory", "other")
            caplog.clear()
            with caplog.at_level(logging.INFO):
                for i in range(FLOOD):
                    await client.send({"op": "call_service", "service": BROKEN, "id": i})
                for i in range(FLOOD):
                    reply = await client.expect(is_op("service_response", id=i))
                    assert reply["result"] is False
                    assert "a bug in the robot's handler" in reply["values"]
                await served(other, "after")
            lines = rwt_lines(caplog)
            assert 1 <= len(lines) <= MAX_LINES, lines
            tracebacks = [r for r in caplog.records if r.exc_info]
            assert len(tracebacks) <= 1


@pytest.mark.parametrize("transport", TRANSPORTS)
async def test_denied_ops_log_once_per_episode(
    transport: str, caplog: pytest.LogCaptureFixture
) -> None:
    config = ServerConfig(session=SessionConfig(access=AccessPolicy(topics=("/public",))))
    with anyio.fail_after(TIMEOUT_S):
        async with running_server(config) as harness:
            client = await harness.connect(transport)
            other = await harness.connect("memory", "other")
            caplog.clear()
            with caplog.at_level(logging.INFO):
                for i in range(FLOOD):
                    await client.send({"op": "subscribe", "topic": "/secret", "id": f"s{i}"})
                await client.expect(is_op("status", id=f"s{FLOOD - 1}"))
                await served(other, "after")
            # episodes are per server process: an earlier case may have opened this one
            lines = rwt_lines(caplog)
            assert len(lines) <= MAX_LINES, lines


async def test_refused_auth_on_many_connections_logs_once_per_episode(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Episodes are per process and keyed by kind: another test's refused auth within
    # 10 s would have opened this one, and its first line would not come.
    monkeypatch.setattr(gates, "_episodes", core_ratelog.EpisodeLog(gates.logger))
    monkeypatch.setattr(rosauth, "_episodes", ratelog.EpisodeLog(rosauth.logger))
    graph = Graph()
    authenticator = rosauth_authenticator("secret", graph.clock)
    bad = {
        "op": "auth",
        "mac": "0" * 128,
        "client": "127.0.0.1",
        "dest": "127.0.0.1",
        "rand": "r",
        "t": graph.clock.wall(),
        "level": "user",
        "end": graph.clock.wall() + 60,
    }
    with anyio.fail_after(TIMEOUT_S):
        async with running_server(graph=graph, authenticator=authenticator) as harness:
            caplog.clear()
            with caplog.at_level(logging.INFO):
                for i in range(FLOOD):
                    stream = await anyio.connect_tcp("127.0.0.1", harness.port("tcp"))
                    async with stream:
                        await stream.send(json.dumps(bad).encode() + b"\n")
                        reply = await stream.receive()
                        assert b"authentication failed" in reply, (i, reply)
            lines = rwt_lines(caplog)
            assert 1 <= len(lines) <= 2 * MAX_LINES, lines


@asynccontextmanager
async def video(graph: Graph) -> AsyncIterator[httpx.AsyncClient]:
    async with anyio.create_task_group() as tg:
        url = await tg.start(serve_video, graph, VideoConfig(port=0))
        async with httpx.AsyncClient(base_url=url, timeout=TIMEOUT_S) as client:
            yield client
        tg.cancel_scope.cancel()


async def test_streams_started_and_stopped_per_request_log_once_per_episode(
    caplog: pytest.LogCaptureFixture,
) -> None:
    graph = Graph()
    graph.create_publisher("/camera", "sensor_msgs/msg/Image")
    with anyio.fail_after(TIMEOUT_S):
        async with video(graph) as client:
            caplog.clear()
            with caplog.at_level(logging.INFO):
                for _ in range(VIDEO_FLOOD):  # no /camera/compressed: each falls back to mjpeg
                    params = {"topic": "/camera", "type": "ros_compressed"}
                    async with client.stream("GET", "/stream", params=params) as response:
                        assert response.status_code == 200
                    while graph.topics["/camera"].subscribers:  # the stream stopped
                        await anyio.sleep(0.001)
                snapshot = await client.get("/snapshot", params={"topic": "/nothing"})
                assert snapshot.status_code == 404  # still serving
            lines = rwt_lines(caplog, logging.INFO)
            assert 1 <= len(lines) <= 3 * MAX_LINES, lines
