"""A Zenoh peer's sample reaches a Foxglove client as the CDR that came over Zenoh.

Two graphs in one process, linked over Zenoh on loopback (``linked``): what
graph B's link received is the ``MessageEvent.wire`` of B's event, and B's
Foxglove client gets those bytes without any serialization made for it. What a
Foxglove client of B publishes reaches a subscriber of A.
"""

from __future__ import annotations

import struct

import pytest

from rwt_graph.rosapi.listing import publishers, subscribers
from rwt_graph.rosapi.visibility import EVERYTHING
from rwt_protocol.ports import ClientId, MessageEvent
from tests.foxglove.sansio import cdr
from tests.foxglove.test_session import Client

from .support import until
from .test_link_embedded import linked

pytestmark = pytest.mark.anyio

STRING = "std_msgs/msg/String"


async def test_a_zenoh_sample_is_passed_to_foxglove_as_it_came() -> None:
    async with linked(2) as [(a, _), (b, _)]:
        talker = a.create_publisher("/fg_point", "geometry_msgs/msg/Point", node="/talker")
        seen: list[MessageEvent] = []

        def tap(entry: object, event: MessageEvent, client: ClientId, latch: bool) -> None:
            seen.append(event)

        b.port.taps.append(tap)
        await until(lambda: "/fg_point" in b.topics, "B mirrors the publisher")
        client = Client(b)
        channel = client.channel("/fg_point")
        client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]})
        await until(lambda: a.topics["/fg_point"].subscribers, "A sees B's subscription")
        talker.publish({"x": 1.0, "y": 2.0, "z": 3.0})
        await until(lambda: bool(seen), "the sample in B")
        client.drain()
        ((_, _, payload),) = client.data()
        (event,) = seen
        assert event.wire is not None and payload == event.wire
        assert event.encodings_made == 0  # nobody serialized it in B


async def test_a_foxglove_clients_publish_reaches_a_zenoh_peer() -> None:
    async with linked(2) as [(a, _), (b, _)]:
        heard: list[dict[str, object]] = []
        a.create_subscription("/fg_from_fox", heard.append, "std_msgs/msg/String", node="/listener")
        client = Client(b)
        channel = {"id": 3, "topic": "/fg_from_fox", "encoding": "cdr"}
        client.send({"op": "advertise", "channels": [{**channel, "schemaName": "std_msgs/String"}]})
        await until(lambda: bool(publishers(a, EVERYTHING, "/fg_from_fox")), "A sees the client")
        await until(lambda: "/listener" in subscribers(b, EVERYTHING, "/fg_from_fox"), "B sees A")
        client.send_raw(
            b"\x01" + struct.pack("<I", 3) + cdr(b, STRING, {"data": "hi"}), binary=True
        )
        await until(lambda: bool(heard), "the message in A")
        assert heard == [{"data": "hi"}]
        assert client.take_ops("status") == []
