"""A bug in one connection closes that connection only (docs/limits.md, containment).

The fault is injected (a session method that raises, as any future bug would), so
these tests hold whatever input would trigger one: the server keeps serving every
other client, on every transport, and the faulty connection is closed cleanly.
"""

from __future__ import annotations

import json
import logging
import os

import anyio
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from rwt_graph.graph import Graph
from rwt_protocol.server.session import Session
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.support.clients import (
    Client,
    Harness,
    PipeStream,
    StreamClient,
    WsClient,
    is_op,
)

pytestmark = pytest.mark.anyio

TIMEOUT_S = 10


@pytest.fixture
def faulty_frames(monkeypatch: pytest.MonkeyPatch) -> None:
    """Any frame holding ``boom`` raises inside the session: a stand-in for a bug."""
    real = Session.receive_frame

    def receive_frame(self: Session, frame: str | bytes, now: float, *, binary: bool = False):  # type: ignore[no-untyped-def]
        text = frame if isinstance(frame, str) else bytes(frame).decode("latin-1")
        if "boom" in text:
            raise RuntimeError("injected bug")
        return real(self, frame, now, binary=binary)

    monkeypatch.setattr(Session, "receive_frame", receive_frame)


async def served(client: Client, tag: str) -> None:
    await client.send({"op": "call_service", "service": "/rosapi/topics", "id": tag})
    assert (await client.expect(is_op("service_response", id=tag)))["result"] is True


async def assert_closed(client: Client) -> None:
    """The connection was closed by the server: a WebSocket with 1011, a stream at EOF."""
    if isinstance(client, WsClient):
        assert client.ws is not None
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                await client.ws.recv()
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1011
    elif isinstance(client, StreamClient):
        with pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError)):
            while True:
                await client.receive()


@pytest.mark.usefixtures("faulty_frames")
@pytest.mark.parametrize("transport", ["memory", "ws", "tcp", "udp"])
async def test_a_bug_closes_only_its_connection(harness: Harness, transport: str) -> None:
    # (connections are opened outside fail_after: a memory connection's scope outlives it)
    bystander = await harness.connect("tcp" if transport == "ws" else "ws", "bystander")
    victim = await harness.connect(transport, "victim")
    with anyio.fail_after(TIMEOUT_S):
        await served(bystander, "before")
        await served(victim, "victim-before")
        await victim.send({"op": "set_level", "level": "info", "id": "boom"})
        await assert_closed(victim)
        await served(bystander, "after")
    again = await harness.connect(transport, "again")
    with anyio.fail_after(TIMEOUT_S):
        await served(again, "again")
    assert all(not s.closed for s in harness.server.sessions.values())


async def test_a_bug_in_an_async_in_process_service_is_contained() -> None:
    graph = Graph()

    async def broken(request: dict[str, object]) -> dict[str, object]:
        raise RuntimeError("injected bug")

    graph.create_service("/broken", "std_srvs/srv/Trigger", broken)
    server = RosbridgeServer(graph, ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        async with server.connect_memory() as connection:
            with anyio.fail_after(TIMEOUT_S):
                await connection.send({"op": "call_service", "service": "/broken", "id": "1"})
                reply = json.loads(await connection.receive_frame())
                assert reply["op"] == "service_response" and reply["result"] is False
                await connection.send({"op": "call_service", "service": "/rosapi/topics"})
                assert json.loads(await connection.receive_frame())["result"] is True
        server.stop()


BUGGY_LINE = b'{"op":"publish","topic":"/boom","msg":{}}\n'
INTERNAL_ERROR = {"op": "status", "level": "error", "msg": "internal error"}


@pytest.mark.usefixtures("faulty_frames")
@pytest.mark.parametrize("transport", ["ws", "tcp", "udp"])
async def test_a_bug_is_logged_once_and_the_peer_told_before_the_close(
    harness: Harness, transport: str, caplog: pytest.LogCaptureFixture
) -> None:
    bystander = await harness.connect("ws", "bystander")
    victim = await harness.connect(transport, "victim")
    with anyio.fail_after(TIMEOUT_S):
        await served(victim, "victim-before")
        sessions = len(harness.server.sessions)
        caplog.clear()
        with caplog.at_level(logging.ERROR):
            await victim.send_raw(BUGGY_LINE)
            if isinstance(victim, WsClient):
                assert victim.ws is not None
                assert json.loads(await victim.ws.recv()) == INTERNAL_ERROR
                with pytest.raises(ConnectionClosed) as closed:
                    await victim.ws.recv()
                assert closed.value.rcvd is not None
                assert closed.value.rcvd.reason == "internal error"
            else:
                assert await victim.receive() == INTERNAL_ERROR
            while len(harness.server.sessions) == sessions:  # released, UDP peers too
                await anyio.sleep(0.01)
        bugs = [r for r in caplog.records if "event=bug" in r.getMessage()]
        assert len(bugs) == 1 and bugs[0].exc_info is not None
        await served(bystander, "after")


@pytest.mark.usefixtures("faulty_frames")
async def test_a_bug_in_the_stdio_session_ends_it_in_order() -> None:
    """stdio is the server's lifeline (it stops when that session ends): a bug ends the
    session with an error status and the server stops gracefully instead of crashing."""
    to_server_r, to_server_w = os.pipe()
    from_server_r, from_server_w = os.pipe()
    config = ServerConfig(port=0, stdio=True, stdio_fds=(to_server_r, from_server_w))
    server = RosbridgeServer(config=config)
    stdio = StreamClient("stdio", stream=PipeStream(to_server_w, from_server_r))
    try:
        with anyio.fail_after(TIMEOUT_S):
            async with anyio.create_task_group() as tg:
                await tg.start(server.serve)
                async with connect(server.urls["websocket"]) as other:
                    await served(stdio, "hello")
                    await stdio.send_raw(BUGGY_LINE)
                    assert await stdio.receive() == INTERNAL_ERROR
                    with pytest.raises(ConnectionClosed) as closed:
                        await other.recv()
                    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1001
            # serve returned by itself; a crash would have raised out of the task group
        assert server.sessions == {}
    finally:
        for fd in (to_server_r, from_server_w):
            os.close(fd)
        assert stdio.stream is not None
        await stdio.stream.aclose()


async def test_a_bug_in_a_subscriber_s_output_spares_the_publisher(
    harness: Harness, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A subscriber's output is written from the publisher's task when the subscriber is
    idle; a bug there belongs to the subscriber's connection, not the publisher's."""
    publisher = await harness.connect("ws", "publisher")
    victim = await harness.connect("ws", "victim")
    with anyio.fail_after(TIMEOUT_S):
        await victim.send({"op": "subscribe", "topic": "/chatter", "type": "std_msgs/String"})
        await served(victim, "subscribed")
        sessions = harness.server.sessions.items()
        victims = {cid for cid, session in sessions if "/chatter" in session.holdings.subscriptions}
        assert len(victims) == 1
        real = Session.frames_to_send

        def frames_to_send(  # type: ignore[no-untyped-def]
            self: Session, max_bytes: int | None = None, now: float | None = None
        ):
            if self.client_id in victims and self.stats.queued_bytes:
                raise RuntimeError("injected bug in a subscriber's output")
            return real(self, max_bytes, now)

        monkeypatch.setattr(Session, "frames_to_send", frames_to_send)
        await publisher.send({"op": "publish", "topic": "/chatter", "msg": {"data": "hi"}})
        await assert_closed(victim)
        await served(publisher, "after")
