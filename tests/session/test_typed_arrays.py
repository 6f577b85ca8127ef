"""CBOR typed arrays stay numpy arrays through the graph (D21, D27; benchmarks B9)."""

from __future__ import annotations

import json

import cbor2
import numpy as np
import pytest

from rwt_graph.graph import Graph
from tests.conftest import Peer


def _publish(peer: Peer, topic: str, msg: dict[str, object]) -> None:
    peer.session.receive_frame(
        cbor2.dumps({"op": "publish", "topic": topic, "msg": msg}), 0.0, binary=True
    )


def _frames(peer: Peer) -> list[dict[str, object]]:
    out = []
    for frame in peer.session.frames_to_send():
        out.append(cbor2.loads(frame.data) if frame.binary else json.loads(frame.data))
    return out


def _grid(cells: bytes) -> dict[str, object]:
    return {"info": {"width": len(cells), "height": 1}, "data": cbor2.CBORTag(72, cells)}


@pytest.fixture
def pub(graph: Graph) -> Peer:
    peer = Peer(graph, "pub")
    peer.send(op="advertise", topic="/map", type="nav_msgs/msg/OccupancyGrid")
    return peer


def test_an_int8_map_reaches_cbor_and_json_subscribers(graph: Graph, pub: Peer) -> None:
    as_cbor, as_json = Peer(graph, "cbor"), Peer(graph, "json")
    as_cbor.send(op="subscribe", topic="/map", compression="cbor")
    as_json.send(op="subscribe", topic="/map")
    seen: list[dict[str, object]] = []
    graph.create_subscription("/map", seen.append, "nav_msgs/msg/OccupancyGrid")
    cells = np.array([-1, 0, 100, 42] * 1000, dtype=np.int8)
    _publish(pub, "/map", _grid(cells.tobytes()))

    [cbor_msg] = [m for m in _frames(as_cbor) if m["op"] == "publish"]
    tag = cbor_msg["msg"]["data"]  # type: ignore[index]
    assert isinstance(tag, cbor2.CBORTag) and tag.tag == 72
    assert tag.value == cells.tobytes()
    [json_msg] = [m for m in _frames(as_json) if m["op"] == "publish"]
    assert json_msg["msg"]["data"] == cells.tolist()  # type: ignore[index]
    # In-process subscribers get the array itself, of the field's element type.
    [msg] = seen
    assert isinstance(msg["data"], np.ndarray) and msg["data"].dtype == np.int8
    assert np.array_equal(msg["data"], cells)


def test_a_wider_typed_array_is_checked_against_the_field_range(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/map")
    fits = np.array([1, -2, 3], dtype=">i4")  # big-endian int32 (tag 74) for int8 cells
    _publish(pub, "/map", {"data": cbor2.CBORTag(74, fits.tobytes())})
    too_big = np.array([1, 300, 3], dtype="<i2")
    _publish(pub, "/map", {"data": cbor2.CBORTag(77, too_big.tobytes())})
    [published] = [m for m in sub.received() if m["op"] == "publish"]
    assert published["msg"]["data"] == [1, -2, 3]  # type: ignore[index]
    [status] = pub.statuses()
    assert status["level"] == "error"
    assert "expected int8 in [-128, 127], got 300 at $.msg.data[1]" in str(status["msg"])


def test_a_float_array_for_an_int_field_is_refused_like_a_list(pub: Peer) -> None:
    floats = np.array([0.5], dtype="<f8")
    _publish(pub, "/map", {"data": cbor2.CBORTag(86, floats.tobytes())})
    [status] = pub.statuses()
    assert "expected int8, got float at $.msg.data[0]" in str(status["msg"])


def test_float_arrays_keep_their_values(graph: Graph) -> None:
    pub, sub = Peer(graph, "pub"), Peer(graph, "sub")
    pub.send(op="advertise", topic="/f", type="std_msgs/msg/Float32MultiArray")
    sub.send(op="subscribe", topic="/f", compression="cbor")
    _publish(pub, "/f", {"data": cbor2.CBORTag(86, np.array([0.1, 2.5]).tobytes())})
    _publish(pub, "/f", {"data": cbor2.CBORTag(86, np.array([1e39]).tobytes())})
    [message] = [m for m in _frames(sub) if m["op"] == "publish"]
    tag = message["msg"]["data"]  # type: ignore[index]
    assert tag.tag == 85  # float32 field: sent as float32 (REF §3.2)
    assert np.frombuffer(tag.value, "<f4").tolist() == pytest.approx([0.1, 2.5])
    [status] = pub.statuses()
    assert "expected float32 in" in str(status["msg"])
    assert str(status["msg"]).endswith("got 1e+39 at $.msg.data[0]")


def test_byte_arrays_from_typed_arrays(graph: Graph) -> None:
    pub, sub = Peer(graph, "pub"), Peer(graph, "sub")
    pub.send(op="advertise", topic="/img", type="sensor_msgs/msg/Image")
    sub.send(op="subscribe", topic="/img", compression="cbor")
    pixels = bytes(range(256))
    _publish(pub, "/img", {"data": cbor2.CBORTag(64, pixels)})  # uint8[] as a typed array
    [message] = [m for m in _frames(sub) if m["op"] == "publish"]
    assert message["msg"]["data"] == pixels  # type: ignore[index]


def test_fixed_arrays_keep_their_length_rule(graph: Graph) -> None:
    pub = Peer(graph, "pub")
    pub.send(op="advertise", topic="/imu", type="sensor_msgs/msg/Imu")
    wrong = np.zeros(8, dtype="<f8")
    _publish(pub, "/imu", {"orientation_covariance": cbor2.CBORTag(86, wrong.tobytes())})
    [status] = pub.statuses()
    assert "expected 9 elements, got 8 at $.msg.orientation_covariance" in str(status["msg"])
