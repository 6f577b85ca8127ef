"""A Foxglove client's queue in the server's flow control (rwt_transports.foxglove).

A rosbridge or Foxglove client publishing a burst larger than a Foxglove
client's queue waits while that client reads, as it would for a rosbridge
subscriber: the Foxglove client gets the whole burst, in order, and hears of no
drop. A
Foxglove client that does not read is left to drop its own oldest data, and
the publisher's burst still reaches a rosbridge subscriber beside it whole
(docs/limits.md, "Backpressure").
"""

from __future__ import annotations

import json
import socket
import struct
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect

from rwt_foxglove import FoxgloveLimits
from rwt_graph.graph import Graph
from rwt_graph.types import TypeRegistry
from rwt_graph.types.registry import codec_for
from rwt_transports.foxglove import FoxgloveOptions
from rwt_transports.server import RosbridgeServer, ServerConfig

pytestmark = pytest.mark.anyio

BURST = 2000
SIZE = 10_000  # 20 MB in all: far more than the sockets' buffers hold
LIMITS = FoxgloveLimits(max_queue_messages=128)


@asynccontextmanager
async def serving(graph: Graph) -> AsyncIterator[RosbridgeServer]:
    config = ServerConfig(port=0, foxglove=FoxgloveOptions(limits=LIMITS))
    server = RosbridgeServer(graph, config)
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        try:
            with anyio.fail_after(60):
                yield server
        finally:
            tg.cancel_scope.cancel()


@asynccontextmanager
async def foxglove(
    server: RosbridgeServer, topic: str, *, rcvbuf: int | None = None
) -> AsyncIterator[ClientConnection]:
    """A Foxglove client subscribed to ``topic`` (subscription id 5)."""
    async with connect(
        server.urls["websocket"],
        subprotocols=["foxglove.sdk.v1"],  # type: ignore[list-item]
        max_size=None,
        max_queue=4 if rcvbuf else 16,
        # one that stopped reading never reads the server's answer to its close
        # (it is behind the data it left): it drops the connection at once
        close_timeout=0 if rcvbuf else 10,
    ) as ws:
        if rcvbuf is not None:
            sock: socket.socket = ws.transport.get_extra_info("socket")
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        while True:
            frame = await ws.recv()
            if isinstance(frame, str) and json.loads(frame)["op"] == "advertise":
                channel = next(c for c in json.loads(frame)["channels"] if c["topic"] == topic)
                break
        subscription = {"id": 5, "channelId": channel["id"]}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [subscription]}))
        yield ws


async def _subscribed(graph: Graph, topic: str, count: int) -> None:
    while len(graph.port.topics[topic].subscribers) < count:  # looked at: no event for it
        await anyio.sleep(0.01)


def _text(index: int) -> str:
    return f"m{index} ".ljust(SIZE, "x")


async def _publish_burst(ws: ClientConnection) -> None:
    await ws.send(json.dumps({"op": "advertise", "topic": "/burst", "type": "std_msgs/String"}))
    for index in range(BURST):
        msg = {"op": "publish", "topic": "/burst", "msg": {"data": _text(index)}}
        await ws.send(json.dumps(msg))


async def _publish_burst_from_foxglove(ws: ClientConnection) -> None:
    channel = {"id": 1, "topic": "/burst", "encoding": "json", "schemaName": "std_msgs/String"}
    await ws.send(json.dumps({"op": "advertise", "channels": [channel]}))
    for index in range(BURST):
        await ws.send(struct.pack("<BI", 1, 1) + json.dumps({"data": _text(index)}).encode())


@pytest.mark.parametrize("protocol", ["rosbridge", "foxglove"])
async def test_a_burst_from_a_client_reaches_a_reading_foxglove_client_whole(
    ros2_types: TypeRegistry, protocol: str
) -> None:
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/burst", "std_msgs/msg/String")  # advertises the topic
    mtype = graph.registry.message("std_msgs/msg/String")
    codec = codec_for(graph.registry, mtype)
    foxglove_publisher = ["foxglove.sdk.v1"] if protocol == "foxglove" else None
    async with (
        serving(graph) as server,
        foxglove(server, "/burst") as fox,
        connect(server.urls["websocket"], subprotocols=foxglove_publisher) as sender,  # type: ignore[arg-type]
    ):
        await _subscribed(graph, "/burst", 1)
        got: list[bytes] = []
        statuses: list[str] = []

        async def read() -> None:
            while len(got) < BURST:
                frame = await fox.recv()
                if isinstance(frame, bytes):
                    assert struct.unpack_from("<I", frame, 1) == (5,)
                    got.append(frame[13:])
                    if len(got) % 50 == 0:
                        await anyio.sleep(0.02)  # reads, slower than the burst comes
                elif json.loads(frame)["op"] == "status":
                    statuses.append(json.loads(frame)["message"])
                    if "dropped" in statuses[-1]:
                        tg.cancel_scope.cancel()  # lost already: no need to read on

        async with anyio.create_task_group() as tg:
            tg.start_soon(read)
            if protocol == "foxglove":
                await _publish_burst_from_foxglove(sender)
            else:
                await _publish_burst(sender)
    expected = [
        bytes(codec.serialize(mtype.from_python({"data": _text(index)}))) for index in range(BURST)
    ]
    assert got == expected
    assert not any("dropped" in status for status in statuses)
    publisher.close()


async def test_a_foxglove_client_that_does_not_read_holds_no_publisher_for_long(
    ros2_types: TypeRegistry,
) -> None:
    graph = Graph(ros2_types)
    graph.create_publisher("/burst", "std_msgs/msg/String")
    async with (
        serving(graph) as server,
        foxglove(server, "/burst", rcvbuf=4096),  # subscribed, never reads again
        connect(server.urls["websocket"]) as subscriber,
        connect(server.urls["websocket"]) as rosbridge,
    ):
        await subscriber.send(
            json.dumps({"op": "subscribe", "topic": "/burst", "type": "std_msgs/String"})
        )
        await _subscribed(graph, "/burst", 2)
        async with anyio.create_task_group() as tg:
            tg.start_soon(_publish_burst, rosbridge)
            data = []
            while len(data) < BURST:
                op = json.loads(await subscriber.recv())
                data.append(op["msg"]["data"])
    assert data == [_text(index) for index in range(BURST)]
