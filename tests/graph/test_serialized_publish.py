"""A message published serialized (``LocalPublisher.publish(bytes)``), as rclpy's publish takes one.

Subscribers that send the wire form (cbor-raw here; Foxglove in
tests/foxglove/test_passthrough.py) get the bytes as they were published;
the others (rosbridge JSON and CBOR, Python callbacks) get the values, decoded
once for all of them on first use. Bytes that do not decode reach those
subscribers as an error, never the publisher or another subscriber.
"""

from __future__ import annotations

import json
import logging

import cbor2
import pytest
from tests.conftest import Peer

from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_graph.types.wire import CdrError, WireCodec
from rwt_protocol.ports import MessageEvent

POINT = "geometry_msgs/msg/PointStamped"
VALUES = {
    "header": {"stamp": {"sec": 7, "nanosec": 8}, "frame_id": "map"},
    "point": {"x": 1.0, "y": -2.0, "z": 0.5},
}


def serialized(graph: Graph, values: dict[str, object] = VALUES, type_name: str = POINT) -> bytes:
    mtype = graph.registry.message(type_name)
    return graph.registry.serialize(mtype, mtype.from_python(values))


def messages(peer: Peer) -> list[object]:
    out: list[object] = []
    for frame in peer.session.frames_to_send():
        op = cbor2.loads(frame.data) if frame.binary else json.loads(frame.data)
        out.append(op["msg"] if op["op"] == "publish" else op)
    return out


@pytest.fixture
def decodes(monkeypatch: pytest.MonkeyPatch) -> list[bytes]:
    """Every decode of a serialized message, counted."""
    seen: list[bytes] = []
    real = WireCodec.deserialize

    def counting(self: WireCodec, data: bytes) -> dict[str, object]:
        seen.append(data)
        return real(self, data)

    monkeypatch.setattr(WireCodec, "deserialize", counting)
    return seen


def test_every_kind_of_subscriber_gets_the_message(graph: Graph, decodes: list[bytes]) -> None:
    heard: list[dict[str, object]] = []
    graph.create_subscription("/point", heard.append, POINT)
    publisher = graph.create_publisher("/point", POINT)
    as_json, as_cbor, as_raw = Peer(graph, "json"), Peer(graph, "cbor"), Peer(graph, "raw")
    for peer, compression in ((as_json, "none"), (as_cbor, "cbor"), (as_raw, "cbor-raw")):
        peer.send(op="subscribe", topic="/point", compression=compression)
    data = serialized(graph)

    publisher.publish(data)

    assert heard == [VALUES]
    assert messages(as_json) == [VALUES]
    assert messages(as_cbor) == [VALUES]
    ((raw,),) = [[m["bytes"] for m in messages(as_raw)]]  # type: ignore[index]
    assert raw == data  # the bytes as published, not serialized again
    assert len(decodes) == 1  # once, for every subscriber that needed the values


def test_bytearray_and_memoryview_are_serialized_messages_too(graph: Graph) -> None:
    heard: list[dict[str, object]] = []
    graph.create_subscription("/point", heard.append, POINT)
    publisher = graph.create_publisher("/point", POINT)
    data = serialized(graph)
    publisher.publish(bytearray(data))
    publisher.publish(memoryview(data))
    assert heard == [VALUES, VALUES]


def test_only_the_subscribers_that_need_values_decode(graph: Graph, decodes: list[bytes]) -> None:
    raw = Peer(graph, "raw")
    raw.send(op="subscribe", topic="/point", type=POINT, compression="cbor-raw")
    publisher = graph.create_publisher("/point", POINT)
    publisher.publish(serialized(graph))
    assert len(messages(raw)) == 1
    assert decodes == []


def test_a_latched_serialized_message_reaches_a_late_subscriber(graph: Graph) -> None:
    publisher = graph.create_publisher("/point", POINT, latch=True)
    publisher.publish(serialized(graph))
    heard: list[dict[str, object]] = []
    graph.create_subscription("/point", heard.append, POINT)
    late = Peer(graph, "late")
    late.send(op="subscribe", topic="/point")
    assert heard == [VALUES]
    assert messages(late) == [VALUES]


def test_a_ros1_graph_takes_the_ros1_format() -> None:
    graph = Graph(TypeRegistry(Dialect.ROS1))
    heard: list[dict[str, object]] = []
    graph.create_subscription("/chatter", heard.append, "std_msgs/String")
    publisher = graph.create_publisher("/chatter", "std_msgs/String")
    data = serialized(graph, {"data": "hello"}, "std_msgs/String")
    assert data == b"\x05\x00\x00\x00hello"  # no CDR header in ROS 1
    publisher.publish(data)
    assert heard == [{"data": "hello"}]


@pytest.mark.parametrize("data", [b"", b"\x00\x01", b"\x01\x00\x00\x00abcd", b"{}"])
def test_bytes_without_a_cdr_header_are_refused_at_publish(graph: Graph, data: bytes) -> None:
    heard: list[dict[str, object]] = []
    graph.create_subscription("/point", heard.append, POINT)
    publisher = graph.create_publisher("/point", POINT)
    with pytest.raises(CdrError, match="encapsulation header"):
        publisher.publish(data)
    assert heard == []


def test_bytes_that_do_not_decode_reach_subscribers_as_an_error(
    graph: Graph, decodes: list[bytes], caplog: pytest.LogCaptureFixture
) -> None:
    heard: list[dict[str, object]] = []
    graph.create_subscription("/point", heard.append, POINT)
    publisher = graph.create_publisher("/point", POINT)
    reader, raw = Peer(graph, "reader"), Peer(graph, "raw")
    reader.send(op="subscribe", topic="/point")
    raw.send(op="subscribe", topic="/point", compression="cbor-raw")
    good = serialized(graph)
    truncated = good[:10]

    with caplog.at_level(logging.ERROR, logger="rwt.graph"):
        publisher.publish(truncated)  # the publisher is not told: it vouched for the bytes
    publisher.publish(good)

    assert heard == [VALUES]  # the callback never saw the bad one; the next came
    assert "callback of the subscription to /point failed" in caplog.text
    got = messages(reader)
    assert got[0]["level"] == "error"  # type: ignore[index]
    assert "cannot send a message of /point" in got[0]["msg"]  # type: ignore[index]
    assert got[1:] == [VALUES]
    assert [m["bytes"] for m in messages(raw)] == [truncated, good]  # type: ignore[index]
    assert decodes.count(truncated) == 1  # the failure is kept, not decoded again


def test_an_event_without_values_needs_its_wire_and_codec(graph: Graph) -> None:
    with pytest.raises(ValueError, match="needs msg"):
        MessageEvent("/point", POINT, None, 0.0, wire=serialized(graph))


def test_a_closed_publisher_refuses_serialized_messages(graph: Graph) -> None:
    publisher = graph.create_publisher("/point", POINT)
    publisher.close()
    with pytest.raises(Exception, match="was closed"):
        publisher.publish(serialized(graph))


@pytest.mark.parametrize("form", ["serialized", "values"])
def test_a_closed_publisher_refuses_while_another_keeps_the_topic(graph: Graph, form: str) -> None:
    """Closed, a publisher sends nothing, though its topic lives on for another one."""
    heard: list[dict[str, object]] = []
    graph.create_subscription("/point", heard.append, POINT)
    keeper = graph.create_publisher("/point", POINT)
    publisher = graph.create_publisher("/point", POINT)
    message = serialized(graph) if form == "serialized" else VALUES
    publisher.publish(message)
    publisher.close()
    with pytest.raises(Exception, match="was closed"):
        publisher.publish(message)
    keeper.publish(message)
    assert len(heard) == 2
    assert heard[0]["point"] == heard[1]["point"] == VALUES["point"]


def test_a_clients_serialized_publish_is_checked_once_and_passed_on_as_the_same_object(
    graph: Graph, decodes: list[bytes], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``GraphPort.publish_serialized`` (a Foxglove client's CDR): one decode, no serialization."""
    graph.create_publisher("/point", POINT)  # the topic's type is known
    raw = Peer(graph, "raw")
    raw.send(op="subscribe", topic="/point", compression="cbor-raw")
    as_json = Peer(graph, "json")
    as_json.send(op="subscribe", topic="/point")
    events: list[MessageEvent] = []
    graph.port.subscribe("probe", "/point", None, _Probe(events))
    data = serialized(graph)
    monkeypatch.setattr(WireCodec, "serialize", lambda self, msg: pytest.fail("serialized"))
    graph.port.publish_serialized("ws:9", "/point", data, encoding="cdr")
    [event] = events
    assert event.wire is data  # the very object, for every subscriber that sends it
    assert decodes == [data]  # the check; JSON subscribers take its values
    [frame] = raw.session.frames_to_send()
    assert cbor2.loads(frame.data)["msg"]["bytes"] == data
    assert messages(as_json) == [VALUES]
    with pytest.raises(CdrError):
        graph.port.publish_serialized("ws:9", "/point", data[:-9], encoding="cdr")
    assert len(events) == 1  # refused: nobody got it


class _Probe:
    def __init__(self, events: list[MessageEvent]) -> None:
        self.events = events

    def on_message(self, event: MessageEvent) -> None:
        self.events.append(event)
