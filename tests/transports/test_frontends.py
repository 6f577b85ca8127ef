"""A third protocol, registered through the front-end registry, gets the server's rules.

docs/architecture.md, "How to add a protocol": a session that subclasses
``SessionBase`` and a ``FrontEnd`` that makes it, handed to ``RosbridgeServer``
(``add_frontend``), and nothing else. The protocol is a few lines
(tests/support/echo.py: "sub TOPIC" subscribes, any other text is echoed); what
it never restates comes from the server, over a real WebSocket: admission
(``--max-connections``), ``--max-subscriptions``, the access globs (with their
log), the idle timeout, and the slow-consumer rule (a client that reads nothing
loses its oldest data and is closed after ``--send-timeout``) and a bug in a
handler contained.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from rwt_graph.graph import Graph
from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.runtime import access
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.support.echo import ECHO, FRONTEND
from tests.support.rawws import masked_text, raw_websocket

pytestmark = pytest.mark.anyio


@asynccontextmanager
async def serving(graph: Graph, **config: object) -> AsyncIterator[RosbridgeServer]:
    server = RosbridgeServer(graph, ServerConfig(port=0, **config))  # type: ignore[arg-type]
    server.add_frontend(FRONTEND)
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        try:
            with anyio.fail_after(60):
                yield server
        finally:
            tg.cancel_scope.cancel()


async def test_the_registry_picks_it_by_subprotocol_and_rosbridge_stays_the_default() -> None:
    async with serving(Graph()) as server:
        url = server.urls["websocket"]
        async with connect(url, subprotocols=[ECHO]) as ws:  # type: ignore[list-item]
            assert ws.subprotocol == ECHO
            await ws.send("hello")
            assert await ws.recv() == "hello"
            await ws.send("boom")  # a bug: reported, and the connection goes on
            assert await ws.recv() == "error: internal error"
            await ws.send("still here")
            assert await ws.recv() == "still here"
        async with connect(url) as ws:  # no subprotocol: rosbridge
            await ws.send('{"op": "call_service", "service": "/rosapi/topics", "id": "1"}')
            assert '"service_response"' in str(await ws.recv())


async def test_admission_limits_and_access_rules_bind_it(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(access, "_episodes", EpisodeLog(access.logger))  # a new episode
    graph = Graph()
    for topic in ("/a", "/b", "/secret"):
        graph.create_publisher(topic, "std_msgs/msg/String")
    session = SessionConfig(max_subscriptions=1, access=AccessPolicy(topics=("/a", "/b")))
    async with serving(graph, max_connections=1, session=session) as server:
        url = server.urls["websocket"]
        async with connect(url, subprotocols=[ECHO]) as ws:  # type: ignore[list-item]
            with pytest.raises(InvalidStatus) as refused:  # --max-connections: any protocol
                async with connect(url):
                    pass
            assert refused.value.response.status_code == 503
            await ws.send("sub /secret")
            assert await ws.recv() == "error: topic /secret is not allowed on this server"
            await ws.send("sub /a")
            await ws.send("sub /b")
            assert await ws.recv() == (
                "error: subscriptions: this connection holds 1 already (the server's limit)"
            )
    assert "event=access_denied" in caplog.text and "op=sub" in caplog.text


async def test_the_idle_timeout_closes_it_unless_it_holds_something() -> None:
    graph = Graph()
    graph.create_publisher("/a", "std_msgs/msg/String")
    async with serving(graph, idle_timeout_s=0.5) as server:
        url = server.urls["websocket"]
        async with (
            connect(url, subprotocols=[ECHO]) as idle,  # type: ignore[list-item]
            connect(url, subprotocols=[ECHO]) as holding,  # type: ignore[list-item]
        ):
            await holding.send("sub /a")
            with pytest.raises(ConnectionClosed) as closed:
                await idle.recv()
            assert closed.value.rcvd is not None and "idle" in closed.value.rcvd.reason
            await holding.send("ping")  # still served
            assert await holding.recv() == "ping"


async def test_a_client_that_reads_nothing_loses_its_oldest_data_and_is_closed(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    graph = Graph()
    fast = graph.create_publisher("/fast", "std_msgs/msg/String")
    session = SessionConfig(send_buffer_limit=64 * 1024, send_timeout_s=0.5)
    async with serving(graph, session=session) as server:
        stalled = await raw_websocket(server.urls["websocket"], ECHO)
        assert b" 101 " in await stalled.receive()  # from here it reads nothing
        await stalled.send(masked_text(b"sub /fast"))
        while not graph.topics["/fast"].subscribers:
            await anyio.sleep(0.01)
        async with connect(server.urls["websocket"], subprotocols=[ECHO]) as bystander:  # type: ignore[list-item]
            while "closed by server: slow consumer" not in caplog.text:
                fast.publish({"data": "x" * 1000})
                await bystander.send("ping")
                assert await bystander.recv() == "ping"  # the bystander is served all along
        await stalled.aclose()
    assert "event=slow_consumer" in caplog.text and "protocol=echo" in caplog.text
