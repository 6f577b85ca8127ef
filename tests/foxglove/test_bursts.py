"""A burst reaches a Foxglove client whole and in order, however it is written.

A Foxglove client runs on the server's one connection runtime (rwt_transports.pump),
as a rosbridge client does. It must get the same messages, in the same order,
whether its frames were written from the event loop (``deferred-send`` on:
output made outside a reader gathered over loop turns, rwt_transports.gather), each
woke the writer task (off), or websockets framed them (every shortcut off;
message data is a header of the client's own before a shared payload,
``OutFrame.prefix``): bursts of small messages published one per turn, large
ones, and many in one turn.
"""

from __future__ import annotations

import json
import struct
from collections import Counter
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager

import anyio
import anyio.lowlevel
import pytest
from websockets.asyncio.client import ClientConnection, connect

from rwt_graph.graph import Graph
from rwt_graph.types import TypeRegistry
from rwt_graph.types.registry import codec_for
from rwt_protocol.runtime.outbox import OutFrame
from rwt_transports import gather
from rwt_transports.server import RosbridgeServer, ServerConfig
from rwt_transports.websocket import WebSocketChannel
from tests.support.shortcuts import switch_off

pytestmark = [pytest.mark.anyio, pytest.mark.uvloop_too]  # the paths differ under uvloop


@asynccontextmanager
async def serving(graph: Graph) -> AsyncIterator[RosbridgeServer]:
    """``graph`` served on a free WebSocket port, for a minute at most."""
    server = RosbridgeServer(graph, ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        try:
            with anyio.fail_after(60):
                yield server
        finally:
            tg.cancel_scope.cancel()


async def _subscribe(ws: ClientConnection, topic: str) -> None:
    while True:
        frame = await ws.recv()
        if isinstance(frame, str) and json.loads(frame)["op"] == "advertise":
            for channel in json.loads(frame)["channels"]:
                if channel["topic"] == topic:
                    subscription = {"id": 7, "channelId": channel["id"]}
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": [subscription]}))
                    return


def _texts() -> list[list[str]]:
    """The burst, by loop turn: small ones one a turn, large ones, then many in one turn."""
    small = [[f"small {i}"] for i in range(300)]
    large = [[f"large {i} ".ljust(100_000 + i, "x")] for i in range(12)]
    together = [[f"together {i}" for i in range(200)]]
    tail = [[f"tail {i}"] for i in range(5)]
    return small + large + together + tail


async def _run_burst(monkeypatch: pytest.MonkeyPatch, off: str | None) -> tuple[list[bytes], int]:
    """The payloads a Foxglove client got for ``_texts``, and the direct writes made."""
    switch_off(monkeypatch, off)
    direct = Counter[str]()
    real = WebSocketChannel.send_now

    def spy(self: WebSocketChannel, frames: Sequence[OutFrame]) -> None:
        direct["writes"] += 1
        real(self, frames)

    monkeypatch.setattr(WebSocketChannel, "send_now", spy)
    # a longer time bound than GATHER_S: a slow machine (turns of a millisecond)
    # would write every message alone within 1 ms
    monkeypatch.setattr(gather, "GATHER_S", 0.5)
    graph = Graph()
    publisher = graph.create_publisher("/burst", "std_msgs/msg/String")
    turns = _texts()
    count = sum(len(turn) for turn in turns)
    async with (
        serving(graph) as server,
        connect(server.urls["websocket"], subprotocols=["foxglove.sdk.v1"], max_size=None) as ws,  # type: ignore[list-item]
    ):
        await _subscribe(ws, "/burst")
        while not graph.port.topics["/burst"].subscribers:  # the subscribe was handled
            await anyio.sleep(0.01)
        for turn in turns:
            for text in turn:
                publisher.publish({"data": text})
            await anyio.lowlevel.checkpoint()
        payloads = []
        while len(payloads) < count:
            frame = await ws.recv()
            if isinstance(frame, bytes):
                assert frame[0] == 1 and struct.unpack_from("<I", frame, 1) == (7,)
                payloads.append(frame[13:])
    return payloads, direct["writes"]


async def test_a_client_gets_the_same_messages_however_they_are_written(
    ros2_types: TypeRegistry,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    direct, direct_writes = await _run_burst(monkeypatch, None)
    general, general_direct = await _run_burst(monkeypatch, "deferred-send")
    framed_by_websockets, _ = await _run_burst(monkeypatch, "1")
    graph = Graph(ros2_types)
    mtype = graph.registry.message("std_msgs/msg/String")
    codec = codec_for(graph.registry, mtype)
    expected = [
        bytes(codec.serialize(mtype.from_python({"data": text})))
        for turn in _texts()
        for text in turn
    ]
    assert direct == expected
    assert general == expected
    assert framed_by_websockets == expected
    assert general_direct == 0  # switched off: the writer task sends every frame
    # on: written from the loop, gathered over turns (rwt_transports.gather): a
    # burst's small messages many to a write, whether one a turn or 200 in one
    assert 0 < direct_writes < len(expected) // 4
