"""Output made outside a reader's batch, gathered over loop turns (rwt_transports.gather).

The gatherer writes a connection once the turn after its first output brings no
more, once it holds ``GATHER_BYTES``, or else (a burst) once ``GATHER_S`` have
passed since the gathering began. Every protocol's connections share it: a
Foxglove client's and a rosbridge subscriber's output from an in-process
publisher both go through it (the burst benchmarks, benchmarks/foxglove.py).
"""

from __future__ import annotations

import asyncio
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
from rwt_protocol.server.outbox import OutFrame
from rwt_transports import gather
from rwt_transports.gather import GATHER_BYTES, Gatherer
from rwt_transports.server import RosbridgeServer, ServerConfig
from rwt_transports.websocket import WebSocketChannel
from tests.support.shortcuts import switch_off

pytestmark = [pytest.mark.anyio, pytest.mark.uvloop_too]  # the loops' clocks differ


class Member:
    """A connection as the gatherer sees it: bytes queued, and when it was flushed."""

    def __init__(self, queued: int = 0) -> None:
        self.queued = queued
        self.flushed_at: int | None = None  # the turn
        self.turn = 0

    def queued_bytes(self) -> int:
        return self.queued

    def flush(self) -> None:
        self.flushed_at = self.turn


async def _turns(members: Sequence[Member], count: int, gatherer: Gatherer | None = None) -> None:
    """Let the loop turn ``count`` times; with ``gatherer``, output comes each turn."""
    for _ in range(count):
        if gatherer is not None:
            gatherer.more = True
        await asyncio.sleep(0)
        for member in members:
            member.turn += 1


async def test_a_lone_output_is_written_after_one_quiet_turn() -> None:
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=3600)
    member = Member()
    gatherer.join(member)
    await _turns([member], 5)
    # the first look waits for the publisher's next turn, the second finds it quiet
    assert member.flushed_at == 1


async def test_output_that_keeps_coming_is_gathered_until_the_time_bound() -> None:
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=0.2)
    member = Member()
    gatherer.join(member)
    await _turns([member], 5, gatherer)  # a message each turn: a burst, gathered
    await _turns([member], 3)  # the burst ended: its tail waits for the bound, no longer
    assert member.flushed_at is None
    with anyio.fail_after(10):
        while member.flushed_at is None:
            await anyio.sleep(0.01)


async def test_a_burst_that_never_ends_is_still_written() -> None:
    gatherer = Gatherer(asyncio.get_running_loop())
    member = Member()
    gatherer.join(member)
    with anyio.fail_after(10):
        while member.flushed_at is None:  # the time bound (GATHER_S) ends the gathering
            await _turns([member], 1, gatherer)


async def test_a_burst_is_gathered_for_its_bound_on_a_clock_finer_than_the_loops() -> None:
    # uvloop's loop.time moves in whole milliseconds: read there, a 1 ms gathering
    # that began just before a tick seemed over at its second look
    now = [0.0]
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=0.001, clock=lambda: now[0])
    member = Member()
    gatherer.join(member)
    now[0] = 0.0004  # the second look: 0.4 ms into the gathering
    await _turns([member], 2, gatherer)  # both looks (the end is on a later turn's timer)
    assert member.flushed_at is None  # a burst: gathered until the bound
    with anyio.fail_after(10):
        while member.flushed_at is None:  # the rest of the bound, on the loop's timer
            await anyio.sleep(0.001)


async def test_a_connection_that_holds_enough_is_written_alone_at_once() -> None:
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=0.2)
    small, full = Member(), Member(GATHER_BYTES)
    gatherer.join(small)
    gatherer.join(full)
    await _turns([small, full], 3, gatherer)
    assert full.flushed_at is not None and full.flushed_at <= 1
    assert small.flushed_at is None  # still gathering while output comes
    with anyio.fail_after(10):
        while small.flushed_at is None:  # written at the bound
            await anyio.sleep(0.01)


async def test_a_connection_that_fills_up_during_a_burst_is_released_at_once() -> None:
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=3600)
    small, filling = Member(), Member()
    gatherer.join(small)
    gatherer.join(filling)
    await _turns([small, filling], 3, gatherer)  # a burst: gathered until the bound
    filling.queued = GATHER_BYTES
    gatherer.release(filling)  # what the pump's wake-up does then
    assert filling.flushed_at == 3
    await _turns([small, filling], 3, gatherer)
    assert small.flushed_at is None


# ---- over a real server ---------------------------------------------------------------


@asynccontextmanager
async def serving(graph: Graph) -> AsyncIterator[RosbridgeServer]:
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
        while not graph.port.topics["/burst"].subscribers:  # subscribed
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


async def test_a_client_gets_the_same_messages_gathered_or_not(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    gathered, direct_writes = await _run_burst(monkeypatch, None)
    general, general_direct = await _run_burst(monkeypatch, "deferred-send")
    framed_by_websockets, _ = await _run_burst(monkeypatch, "1")
    graph = Graph(TypeRegistry())
    mtype = graph.registry.message("std_msgs/msg/String")
    codec = codec_for(graph.registry, mtype)
    expected = [
        bytes(codec.serialize(mtype.from_python({"data": text})))
        for turn in _texts()
        for text in turn
    ]
    assert gathered == expected
    assert general == expected
    assert framed_by_websockets == expected
    assert general_direct == 0  # switched off: the writer task sends every frame
    # on: written from the loop, a burst's small messages many to a write
    assert 0 < direct_writes < len(expected) // 4
