"""A robot's serialized bursts reach a Foxglove client the same, batched in the graph or not.

An embedded robot publishes CDR (``LocalPublisher.publish(bytes)``) on two
topics: messages one a turn (the graph then delivers at once after a batch of
one), runs of one topic, and the two topics interleaved in one turn. The
client subscribed to both must get every message, in publish order across the
topics, with the graph's batched delivery on and with it off
(``RWT_NO_SHORTCUTS=batched-delivery``); on, the Foxglove sink took runs of
several messages in one call (docs/embedding.md, "Batched delivery").
"""

from __future__ import annotations

import json
import struct
from collections import Counter

import anyio
import anyio.lowlevel
import pytest
from websockets.asyncio.client import connect

from rwt_foxglove.session import _TopicSink
from rwt_graph.graph import Graph
from rwt_protocol.ports import MessageEvent
from tests.foxglove.test_bursts import serving
from tests.graph.test_batched_delivery import cdr
from tests.support.shortcuts import switch_off

pytestmark = [pytest.mark.anyio, pytest.mark.uvloop_too]

TOPICS = ("/a", "/b")


def _turns() -> list[list[tuple[str, str]]]:
    """(topic, text) by loop turn: one a turn, runs of one topic, the two interleaved."""
    lone = [[(TOPICS[i % 2], f"lone {i}")] for i in range(40)]
    runs = [[("/a", f"run a {i}") for i in range(150)] + [("/b", f"run b {i}") for i in range(50)]]
    mixed = [[(TOPICS[(i // 3) % 2], f"mixed {i}") for i in range(300)] for _ in range(2)]
    return lone + runs + mixed


async def _burst(
    monkeypatch: pytest.MonkeyPatch, off: str | None
) -> tuple[list[str], Counter[int]]:
    """(topic and text) of each message the client got, and the sizes of the sink's batches."""
    switch_off(monkeypatch, off)
    batches = Counter[int]()
    real = _TopicSink.on_messages

    def spy(self: _TopicSink, events: list[MessageEvent], subscriptions: object = None) -> None:
        batches[len(events)] += 1
        real(self, events, subscriptions)  # type: ignore[arg-type]

    monkeypatch.setattr(_TopicSink, "on_messages", spy)
    graph = Graph()
    publishers = {topic: graph.create_publisher(topic, "std_msgs/msg/String") for topic in TOPICS}
    turns = _turns()
    count = sum(len(turn) for turn in turns)
    got: list[str] = []
    async with (
        serving(graph) as server,
        connect(server.urls["websocket"], subprotocols=["foxglove.sdk.v1"]) as ws,  # type: ignore[list-item]
    ):
        subscribed: dict[int, str] = {}  # subscription id -> topic
        while len(subscribed) < len(TOPICS):
            frame = await ws.recv()
            if isinstance(frame, str) and json.loads(frame)["op"] == "advertise":
                for channel in json.loads(frame)["channels"]:
                    if channel["topic"] in TOPICS:
                        sid = len(subscribed) + 1
                        subscribed[sid] = channel["topic"]
                        subscription = {"id": sid, "channelId": channel["id"]}
                        await ws.send(
                            json.dumps({"op": "subscribe", "subscriptions": [subscription]})
                        )
        while any(not graph.port.topics[topic].subscribers for topic in TOPICS):
            await anyio.sleep(0.01)
        for turn in turns:
            for topic, text in turn:
                publishers[topic].publish(cdr(text))
            await anyio.lowlevel.checkpoint()
        while len(got) < count:
            frame = await ws.recv()
            if isinstance(frame, bytes) and frame[0] == 1:
                (sid,) = struct.unpack_from("<I", frame, 1)
                length = struct.unpack_from("<I", frame, 17)[0]
                got.append(f"{subscribed[sid]} {frame[21 : 21 + length - 1].decode()}")
    return got, batches


async def test_the_client_gets_every_message_in_publish_order_batched_or_not(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    expected = [f"{topic} {text}" for turn in _turns() for topic, text in turn]
    batched, sizes = await _burst(monkeypatch, None)
    general, general_sizes = await _burst(monkeypatch, "batched-delivery")
    assert batched == expected
    assert general == expected
    assert set(general_sizes) == {1}  # off: each message alone
    # on: the runs of a turn in one call each (the first few of the long run may go
    # alone, right after the lone messages: ``SOLO_AFTER_ONE``)
    assert sizes[50] == 1 and max(sizes) > 100
    assert sizes[3] >= 190  # the interleaved turns: runs of three
