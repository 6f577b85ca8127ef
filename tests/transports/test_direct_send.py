"""Frames written from the publish path keep their order with the writer's.

While a connection's writer is idle and its socket has nothing buffered, the
pump writes a publish's frames at once (``send_now``); otherwise the writer task
sends them. A subscriber must see every message in publish order whichever way
each went, on the default loop and on uvloop, over WebSocket and TCP; a TLS
stream always goes through the writer. These are the ``direct-write`` and
``deferred-send`` shortcuts (rwt_protocol.shortcuts): the tests turn them on
whatever ``RWT_NO_SHORTCUTS`` says (connections choose when they are made).
"""

from __future__ import annotations

import ssl
from collections import Counter
from collections.abc import AsyncIterator, Sequence
from pathlib import Path

import anyio
import anyio.lowlevel
import pytest
import trustme

from rwt_graph.graph import Graph
from rwt_protocol.runtime.flow import FlowControl
from rwt_protocol.runtime.outbox import OutFrame
from rwt_protocol.server.session import CloseCode, Session, SessionConfig
from rwt_protocol.shortcuts import ENV_VAR
from rwt_transports.channel import ChannelAbilities
from rwt_transports.holding import Held
from rwt_transports.pump import ConnectionPump, flush_deferred
from rwt_transports.server import ServerConfig
from rwt_transports.tcp import StreamChannel
from rwt_transports.websocket import WebSocketChannel
from tests.conftest import FakeClock
from tests.support.clients import Client, running_server

pytestmark = [pytest.mark.anyio, pytest.mark.uvloop_too]  # the paths differ under uvloop

MiB = 1024 * 1024
BIG = 256 * 1024  # a burst of these fills the loopback socket's buffers
BURST = 128  # 32 MiB: more than the kernel takes without the peer reading


@pytest.fixture(autouse=True)
def shortcuts_on(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)


@pytest.fixture
def paths(monkeypatch: pytest.MonkeyPatch) -> Counter[str]:
    """Counts the frames each channel sent from the publish path and through its writer."""
    counts: Counter[str] = Counter()
    for cls in (WebSocketChannel, StreamChannel):
        send_now, send = cls.send_now, cls.send

        def spy_now(self: object, frames: Sequence[OutFrame], _real: object = send_now) -> None:
            counts["now"] += len(frames)
            _real(self, frames)  # type: ignore[operator]

        async def spy_send(self: object, frames: Sequence[OutFrame], _real: object = send) -> None:
            counts["writer"] += len(frames)
            await _real(self, frames)  # type: ignore[operator]

        monkeypatch.setattr(cls, "send_now", spy_now)
        monkeypatch.setattr(cls, "send", spy_send)
    return counts


async def subscribed(client: Client, topic: str) -> None:
    """Subscribe and wait until the server has done it (ops of a connection run in order)."""
    await client.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    await client.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
    await client.expect(lambda m: m.get("op") == "service_response")


async def numbers(client: Client, count: int) -> list[int]:
    seen = []
    for _ in range(count):
        message = await client.expect(lambda m: m.get("op") == "publish")
        seen.append(int(message["msg"]["data"].split(":", 1)[0]))
    return seen


@pytest.mark.parametrize("transport", ["ws", "tcp"])
async def test_a_burst_beyond_the_socket_buffer_and_then_small_messages_arrive_in_order(
    transport: str, paths: Counter[str]
) -> None:
    graph = Graph(clock=FakeClock())
    config = ServerConfig(session=SessionConfig(send_buffer_limit=64 * MiB))
    async with running_server(config, graph=graph) as harness:
        client = await harness.connect(transport)
        await subscribed(client, "/seq")
        publisher = graph.create_publisher("/seq", "std_msgs/msg/String")
        with anyio.fail_after(30):
            # No await in between: the first go straight out, the kernel soon
            # stops taking more, the rest wait for the writer.
            for i in range(BURST):
                publisher.publish({"data": f"{i}:" + "x" * BIG})
            assert await numbers(client, BURST) == list(range(BURST))
            small = list(range(BURST, BURST + 50))
            for i in small:  # the writer is idle again and the socket empty
                publisher.publish({"data": f"{i}:"})
                await anyio.lowlevel.checkpoint()
            assert await numbers(client, len(small)) == small
    assert paths["now"] >= len(small) and paths["writer"] > 0


async def test_tls_goes_through_the_writer(paths: Counter[str], tmp_path: Path) -> None:
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1")
    certfile, keyfile = tmp_path / "cert.pem", tmp_path / "key.pem"
    cert.cert_chain_pems[0].write_to_path(certfile)
    cert.private_key_pem.write_to_path(keyfile)
    graph = Graph(clock=FakeClock())
    async with running_server(
        ServerConfig(certfile=certfile, keyfile=keyfile), graph=graph
    ) as harness:
        context = ssl.create_default_context()
        ca.configure_trust(context)
        harness.ssl_context = context
        client = await harness.connect("ws")
        await subscribed(client, "/tls")
        publisher = graph.create_publisher("/tls", "std_msgs/msg/String")
        with anyio.fail_after(10):
            for i in range(20):
                publisher.publish({"data": f"{i}:"})
            assert await numbers(client, 20) == list(range(20))
    assert paths["now"] == 0 and paths["writer"] > 0


class FakeChannel:
    """A channel whose direct path can be switched off, recording what went out and how."""

    transport = "fake"
    awaits_peer_close = False
    abilities = ChannelAbilities(send_now=True)

    def __init__(self) -> None:
        self.wire: list[tuple[str, bytes]] = []
        self.ready = True
        self.writes = 0
        self.closed: tuple[CloseCode, str] | None = None
        self.stop = anyio.Event()

    async def receive(self) -> Sequence[object]:
        await self.stop.wait()
        raise anyio.EndOfStream

    async def send(self, frames: Sequence[OutFrame]) -> None:
        await anyio.lowlevel.checkpoint()
        self.writes += 1
        self.wire += [("writer", f.data) for f in frames]

    def can_send_now(self) -> bool:
        return self.ready

    def send_now(self, frames: Sequence[OutFrame]) -> None:
        self.writes += 1
        self.wire += [("now", f.data) for f in frames]

    async def close(self, code: CloseCode, reason: str) -> None:
        self.closed = (code, reason)

    async def background(self, session: Session) -> None:
        return


@pytest.fixture
async def pumped() -> AsyncIterator[tuple[FakeChannel, Session, Graph, FlowControl[Held]]]:
    graph = Graph(clock=FakeClock())
    channel = FakeChannel()
    flow: FlowControl[Held] = FlowControl()
    pump = ConnectionPump(channel, flow)  # type: ignore[arg-type]
    session = Session(graph.port, "sub", on_output=pump.wake)
    session.receive_frame(b'{"op":"subscribe","topic":"/t","type":"std_msgs/String"}', 0.0)
    async with anyio.create_task_group() as tg:
        tg.start_soon(pump.run, session)
        await anyio.wait_all_tasks_blocked()
        yield channel, session, graph, flow
        channel.stop.set()


@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_the_pump_mixes_both_paths_without_reordering(
    pumped: tuple[FakeChannel, Session, Graph, FlowControl[Held]],
) -> None:
    channel, _, graph, flow = pumped
    publisher = graph.create_publisher("/t", "std_msgs/msg/String")

    def publish(*numbers: int) -> None:
        for i in numbers:
            publisher.publish({"data": str(i)})

    publish(0, 1, 2)  # the writer is idle: written together at the end of the batch
    flush_deferred(flow)
    channel.ready = False
    publish(3)  # the socket is busy: the writer is woken
    flush_deferred(flow)
    channel.ready = True
    publish(4)  # behind 3 in the queue: the writer sends both
    await anyio.wait_all_tasks_blocked()
    publish(5)  # idle again: from the loop's gathering when no reader flushes (gather.py)
    with anyio.fail_after(5):
        while len(channel.wire) < 6:  # the gathering ends after a quiet turn of the loop
            await anyio.lowlevel.checkpoint()
    sent = [(path, int(data.split(b'"data":"')[1].split(b'"')[0])) for path, data in channel.wire]
    assert [n for _, n in sent] == list(range(6))
    assert [path for path, _ in sent] == ["now"] * 3 + ["writer"] * 2 + ["now"]
    assert channel.writes == 3  # 0-2 in one write, 3-4 in one: never one system call a frame


@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_a_pending_close_is_left_to_the_writer(
    pumped: tuple[FakeChannel, Session, Graph, FlowControl[Held]],
) -> None:
    channel, session, graph, _ = pumped
    publisher = graph.create_publisher("/t", "std_msgs/msg/String")
    channel.ready = False
    publisher.publish({"data": "queued"})
    session.request_close(CloseCode.NORMAL, "bye")
    channel.ready = True
    with anyio.fail_after(5):
        while channel.closed is None:
            await anyio.wait_all_tasks_blocked()
            await anyio.lowlevel.checkpoint()
    assert [path for path, _ in channel.wire] == ["writer"]
    assert channel.closed == (CloseCode.NORMAL, "bye")
