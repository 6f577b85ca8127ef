"""A Zenoh peer's sample reaches a Foxglove client as the CDR that came over Zenoh.

Two graphs in one process, linked over Zenoh on loopback (``linked``): what
graph B's link received is the ``MessageEvent.wire`` of B's event, and B's
Foxglove client gets those bytes without any serialization made for it.
"""

from __future__ import annotations

import pytest

from rwt_protocol.ports import ClientId, MessageEvent
from tests.foxglove.test_session import Client

from .support import until
from .test_link_embedded import linked

pytestmark = pytest.mark.anyio


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
