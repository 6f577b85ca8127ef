"""Message data is the CDR the graph received, byte for byte, where it received CDR.

A link's sample and a bag's record reach the graph serialized; a Foxglove
client gets those bytes as they came (``MessageEvent.wire``), not a fresh
serialization. The bytes here carry a non-zero alignment padding byte, which
rwt's serializer writes as zero: a payload that still has it was not
serialized again, and ``MessageEvent.encodings_made`` (one count per
serialization made for a subscriber) stays 0.
"""

from __future__ import annotations

from pathlib import Path

import anyio
import pytest
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore

from rwt_bag.player import Player
from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_graph.types.wire import WireCodec

from .test_session import Client

POINT = "geometry_msgs/msg/PointStamped"
VALUES = {
    "header": {"stamp": {"sec": 7, "nanosec": 8}, "frame_id": "ab"},
    "point": {"x": 1.0, "y": -2.0, "z": 0.5},
}
PADDING = 4 + 15  # CDR header, then sec, nanosec, length 3, "ab\0": one byte before the point


def odd_cdr(graph: Graph) -> bytes:
    """``VALUES`` as CDR whose padding byte is 0xAB (valid CDR: readers skip padding)."""
    mtype = graph.registry.message(POINT)
    data = bytearray(graph.registry.serialize(mtype, mtype.from_python(VALUES)))
    assert data[PADDING] == 0
    data[PADDING] = 0xAB
    return bytes(data)


def subscribed(graph: Graph, topic: str) -> Client:
    client = Client(graph)
    channel = client.channel(topic)
    client.send({"op": "subscribe", "subscriptions": [{"id": 3, "channelId": channel["id"]}]})
    return client


def test_a_sample_received_as_cdr_is_sent_as_it_came() -> None:
    graph = Graph()
    graph.port.advertise("link:relay", "/point", POINT)
    client = subscribed(graph, "/point")
    wire = odd_cdr(graph)
    msg = graph.registry.message(POINT).from_python(VALUES)
    event = graph.port.publish_local("link:relay", "/point", msg, latch=False, wire=wire)
    client.drain()
    ((sid, _, payload),) = client.data()
    assert sid == 3 and payload == wire
    assert event.encodings_made == 0  # nobody serialized it


def test_a_message_published_serialized_is_sent_as_published_and_not_decoded(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    graph = Graph()
    publisher = graph.create_publisher("/point", POINT)
    client = subscribed(graph, "/point")
    decodes: list[bytes] = []
    monkeypatch.setattr(WireCodec, "deserialize", lambda self, data: decodes.append(data))
    wire = odd_cdr(graph)
    publisher.publish(wire)  # as the Foxglove SDK's ``Channel.log`` takes CDR
    client.drain()
    ((sid, _, payload),) = client.data()
    assert sid == 3 and payload == wire
    assert decodes == []  # a Foxglove client alone never costs a decode


def test_a_message_published_as_values_is_serialized() -> None:
    graph = Graph()
    publisher = graph.create_publisher("/point", POINT)
    client = subscribed(graph, "/point")
    publisher.publish(VALUES)
    client.drain()
    ((_, _, payload),) = client.data()
    assert payload == odd_cdr(graph)[:PADDING] + b"\0" + odd_cdr(graph)[PADDING + 1 :]


@pytest.mark.anyio
async def test_a_ros2_bag_is_replayed_as_its_records(tmp_path: Path) -> None:
    graph = Graph(TypeRegistry(Dialect.ROS2))
    records = [odd_cdr(graph)]
    mtype = graph.registry.message(POINT)
    other = dict(VALUES, point={"x": 3.0, "y": 4.0, "z": 5.0})
    records.append(bytes(graph.registry.serialize(mtype, mtype.from_python(other))))
    store = get_typestore(Stores.ROS2_JAZZY)
    with Ros2Writer(tmp_path / "bag", version=9) as writer:
        conn = writer.add_connection("/point", POINT, typestore=store)
        for n, record in enumerate(records):
            writer.write(conn, 1_700_000_000 * 10**9 + n * 10**6, record)
    player = Player(graph, [tmp_path / "bag"], paused=True)
    async with anyio.create_task_group() as tasks:
        await tasks.start(player.run)
        client = subscribed(graph, "/point")
        player.resume()
        payloads: list[bytes] = []
        with anyio.fail_after(10):
            while len(payloads) < len(records):
                await anyio.sleep(0.01)
                client.drain()
                payloads += [frame[13:] for frame in client.binary if frame[0] == 1]  # not time
                client.binary = []
        tasks.cancel_scope.cancel()
    assert payloads == records
