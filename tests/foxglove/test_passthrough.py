"""Message data is the CDR the graph received, byte for byte, where it received CDR.

A link's sample and a bag's record reach the graph serialized; a Foxglove
client gets those bytes as they came (``MessageEvent.wire``), not a fresh
serialization. The bytes here carry a non-zero alignment padding byte, which
rwt's serializer writes as zero: a payload that still has it was not
serialized again, and ``MessageEvent.encodings_made`` (one count per
serialization made for a subscriber) stays 0.
"""

from __future__ import annotations

import struct
from pathlib import Path

import anyio
import cbor2
import pytest
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore

from rwt_bag.player import Player
from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_graph.types.wire import WireCodec
from rwt_protocol.errors import GraphError
from rwt_protocol.ports import MessageEvent
from tests.conftest import Peer

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


def test_a_foxglove_clients_cdr_reaches_every_wire_subscriber_as_the_same_bytes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``publish_serialized``: validated by one decode, then passed on, never serialized again.

    (That the graph passes on the very bytes object it was given is
    tests/graph/test_serialized_publish.py's.)
    """
    graph = Graph()
    publisher, reader = Client(graph), Client(graph)
    publisher.send(
        {
            "op": "advertise",
            "channels": [{"id": 1, "topic": "/point", "encoding": "cdr", "schemaName": POINT}],
        }
    )
    raw = Peer(graph, "raw")
    raw.send(op="subscribe", topic="/point", compression="cbor-raw")
    heard: list[dict[str, object]] = []
    graph.create_subscription("/point", heard.append)
    events: list[MessageEvent] = []
    graph.port.subscribe("probe", "/point", None, _Probe(events))
    reader.sync()
    channel = reader.channel("/point")["id"]
    reader.send({"op": "subscribe", "subscriptions": [{"id": 3, "channelId": channel}]})
    wire = odd_cdr(graph)
    decodes: list[bytes] = []
    real = WireCodec.deserialize
    monkeypatch.setattr(
        WireCodec, "deserialize", lambda self, data: decodes.append(data) or real(self, data)
    )
    monkeypatch.setattr(WireCodec, "serialize", lambda self, msg: pytest.fail("serialized"))
    publisher.send_raw(b"\x01" + struct.pack("<I", 1) + wire, binary=True)
    assert publisher.take_ops("status") == []
    [event] = events
    assert event.wire == wire  # the bytes the client sent, one object for every subscriber
    assert decodes == [wire]  # its one check; the values go to the others from it
    assert heard[0]["point"] == VALUES["point"]
    reader.drain()
    ((sid, _, payload),) = reader.data()
    assert sid == 3 and payload == wire  # the 0xAB padding byte too: not serialized again
    [frame] = raw.session.frames_to_send()
    assert cbor2.loads(frame.data)["msg"]["bytes"] == wire


def test_bytes_that_are_not_the_topics_cdr_fail_their_publisher_and_reach_nobody() -> None:
    graph = Graph()
    publisher = Client(graph)
    publisher.send(
        {
            "op": "advertise",
            "channels": [{"id": 1, "topic": "/point", "encoding": "cdr", "schemaName": POINT}],
        }
    )
    events: list[MessageEvent] = []
    graph.port.subscribe("probe", "/point", None, _Probe(events))
    publisher.send_raw(b"\x01" + struct.pack("<I", 1) + b"\x00\x01\x00\x00\x01", binary=True)
    [status] = publisher.take_ops("status")
    assert "not a cdr message" in str(status["message"])
    assert events == []
    with pytest.raises(GraphError, match="not this graph's"):
        graph.port.publish_serialized("ws:2", "/point", odd_cdr(graph), encoding="ros1")
    assert events == []


class _Probe:
    def __init__(self, events: list[MessageEvent]) -> None:
        self.events = events

    def on_message(self, event: MessageEvent) -> None:
        self.events.append(event)
