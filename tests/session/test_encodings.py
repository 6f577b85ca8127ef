"""Encodings through sessions on one graph: CBOR, cbor-raw, PNG, fragments, encode once.

Spec 3.1, 3.3.4; D19-D21, D27; REF §3.2-§3.5.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import cbor2
import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry, codec_for
from rwt_protocol.codecs.png import decode_png, encode_png
from rwt_protocol.framing.fragments import fragment_frames
from rwt_protocol.levels import StatusLevel
from rwt_protocol.ops import ServiceResponse
from rwt_protocol.ops.base import Compression
from rwt_protocol.ports import MessageEvent
from rwt_protocol.runtime.outbox import FRAME_OVERHEAD_BYTES, Outbox, OutFrame
from rwt_protocol.server import encoding
from rwt_protocol.server.session import Session, SessionConfig
from tests.conftest import FakeClock, Peer

DATA = Path(__file__).parents[1] / "graph" / "data" / "interfaces"

MULTI_ARRAYS = {
    "Float32MultiArray": ("float32", 85, "<f4"),
    "Float64MultiArray": ("float64", 86, "<f8"),
    "Int8MultiArray": ("int8", 72, "i1"),
    "Int16MultiArray": ("int16", 77, "<i2"),
    "Int32MultiArray": ("int32", 78, "<i4"),
    "Int64MultiArray": ("int64", 79, "<i8"),
    "UInt16MultiArray": ("uint16", 69, "<u2"),
    "UInt32MultiArray": ("uint32", 70, "<u4"),
    "UInt64MultiArray": ("uint64", 71, "<u8"),
}


def decoded(peer: Peer) -> list[dict[str, object]]:
    """Every frame queued for ``peer``: CBOR for binary frames, JSON for text (D27)."""
    out = []
    for frame in peer.session.frames_to_send():
        out.append(cbor2.loads(frame.data) if frame.binary else json.loads(frame.data))
    return out


def reassemble(frames: list[dict[str, object]]) -> list[dict[str, object]]:
    """What a client makes of fragment and png ops (roslib's rules, plus png parts)."""
    parts: dict[tuple[str, object], dict[int, str]] = {}
    out: list[dict[str, object]] = []
    for frame in frames:
        op, total = frame["op"], frame.get("total")
        if op in ("fragment", "png") and total is not None:
            got = parts.setdefault((str(op), frame["id"]), {})
            got[int(frame["num"])] = str(frame["data"])  # type: ignore[call-overload]
            if len(got) < total:  # type: ignore[operator]
                continue
            whole = "".join(got[i] for i in sorted(got))
            if op == "fragment":
                out += reassemble([json.loads(whole)])
            else:
                out += reassemble([json.loads(decode_png(whole, max_bytes=1 << 24))])
        elif op == "png":
            out += reassemble([json.loads(decode_png(str(frame["data"]), max_bytes=1 << 24))])
        else:
            out.append(frame)
    return out


@pytest.fixture
def pub(graph: Graph) -> Peer:
    return Peer(graph, "pub")


@pytest.mark.parametrize("name", sorted(MULTI_ARRAYS))
def test_cbor_sends_every_multiarray_as_its_typed_array(graph: Graph, pub: Peer, name: str) -> None:
    dtype, tag, packed = MULTI_ARRAYS[name]
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/m", type=f"std_msgs/{name}", compression="cbor")
    values = [0, 1, 2, 100] if "float" not in dtype else [0.5, -1.25, 3.0]
    pub.send(op="publish", topic="/m", msg={"data": values})
    [frame] = sub.session.frames_to_send()
    assert frame.binary
    message = cbor2.loads(frame.data)
    assert message["op"] == "publish" and message["topic"] == "/m"
    data = message["msg"]["data"]
    assert data == cbor2.CBORTag(tag, np.array(values, dtype=packed).tobytes())
    assert message["msg"]["layout"] == {"dim": [], "data_offset": 0}


def test_cbor_sends_uint8_data_as_a_byte_string_and_times_as_maps(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/img", type="sensor_msgs/Image", compression="cbor")
    raw = bytes(range(12))
    header = {"stamp": {"sec": 5, "nanosec": 6}, "frame_id": "cam"}
    image = {"header": header, "height": 2, "width": 2, "encoding": "rgb8", "step": 6}
    pub.send(op="publish", topic="/img", msg={**image, "data": base64.b64encode(raw).decode()})
    [message] = decoded(sub)
    assert message["msg"]["data"] == raw
    assert message["msg"]["header"] == header
    assert message["msg"]["is_bigendian"] == 0


def test_cbor_handles_fixed_and_bounded_arrays(clock: FakeClock) -> None:
    graph = Graph(TypeRegistry(Dialect.ROS2, [DATA]), clock=clock)
    pub, sub = Peer(graph, "pub"), Peer(graph, "sub")
    sub.send(op="subscribe", topic="/l", type="rwt_test_msgs/Limits", compression="cbor")
    pub.send(
        op="publish",
        topic="/l",
        msg={
            "uuid": list(range(16)),
            "covariance": [float(i) for i in range(9)],
            "bounded_floats": [1.5],
            "few_ints": [-1, 2],
            "octets": [255, 0],
            "flags": [True],
        },
    )
    [message] = decoded(sub)
    msg = message["msg"]
    assert msg["uuid"] == bytes(range(16))
    assert msg["covariance"] == cbor2.CBORTag(86, np.arange(9, dtype="<f8").tobytes())
    assert msg["bounded_floats"] == cbor2.CBORTag(85, np.array([1.5], "<f4").tobytes())
    assert msg["few_ints"] == cbor2.CBORTag(78, np.array([-1, 2], "<i4").tobytes())
    assert msg["octets"] == b"\xff\x00"  # ROS 2 byte is an octet
    assert msg["flags"] == [True]
    assert msg["tags"] == []


def test_cbor_in_ros1_uses_secs_and_nsecs_and_signed_bytes(clock: FakeClock) -> None:
    graph = Graph(TypeRegistry(Dialect.ROS1, [DATA]), clock=clock)
    pub, sub = Peer(graph, "pub"), Peer(graph, "sub")
    sub.send(op="subscribe", topic="/s", type="rwt_test_msgs/Stamped", compression="cbor")
    sub.send(op="subscribe", topic="/l", type="rwt_test_msgs/Limits", compression="cbor")
    pub.send(op="publish", topic="/s", msg={"header": {"stamp": {"secs": 1, "nsecs": 2}}})
    pub.send(op="publish", topic="/l", msg={"octets": [-1, 5]})
    stamped, limits = decoded(sub)
    assert stamped["msg"]["header"]["stamp"] == {"secs": 1, "nsecs": 2}
    assert limits["msg"]["octets"] == cbor2.CBORTag(72, b"\xff\x05")


def test_cbor_raw_is_the_cdr_serialization(graph: Graph, pub: Peer, clock: FakeClock) -> None:
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/p", type="geometry_msgs/Point", compression="cbor-raw")
    pub.send(op="publish", topic="/p", msg={"x": 1.0, "y": 2.0, "z": 3.0})
    [message] = decoded(sub)
    assert message["msg"]["secs"] == 1_700_000_000
    assert message["msg"]["nsecs"] == 250_000_000
    raw = message["msg"]["bytes"]
    assert raw[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation header
    store = graph.registry.typestore()
    point = store.deserialize_cdr(raw, "geometry_msgs/msg/Point")
    assert (point.x, point.y, point.z) == (1.0, 2.0, 3.0)


def test_cbor_raw_sends_what_arrived_serialized_as_it_came(graph: Graph) -> None:
    """A link's sample or a bag's record (``MessageEvent.wire``) is not serialized again."""
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/c", type="std_msgs/String", compression="cbor-raw")
    graph.port.advertise("link:relay", "/c", "std_msgs/msg/String")
    wire = b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00\xee"  # a trailing byte kept as it came
    msg = {"data": "hi"}
    graph.port.publish_local("link:relay", "/c", msg, latch=False, wire=wire)
    [message] = decoded(sub)
    assert message["msg"]["bytes"] == wire  # a serialization would end at the NUL


def test_cbor_raw_in_ros1_is_the_ros1_serialization(clock: FakeClock) -> None:
    graph = Graph(TypeRegistry(Dialect.ROS1), clock=clock)
    pub, sub = Peer(graph, "pub"), Peer(graph, "sub")
    sub.send(op="subscribe", topic="/c", type="std_msgs/String", compression="cbor-raw")
    pub.send(op="publish", topic="/c", msg={"data": "hi"})
    [message] = decoded(sub)
    assert message["msg"]["bytes"] == b"\x02\x00\x00\x00hi"


def test_each_client_gets_its_own_encoding_of_one_topic(graph: Graph, pub: Peer) -> None:
    plain, cbor, raw = Peer(graph, "json"), Peer(graph, "cbor"), Peer(graph, "raw")
    plain.send(op="subscribe", topic="/c", type="std_msgs/String")
    cbor.send(op="subscribe", topic="/c", type="std_msgs/String", compression="cbor")
    raw.send(op="subscribe", topic="/c", type="std_msgs/String", compression="cbor-raw")
    pub.send(op="publish", topic="/c", msg={"data": "hi"})
    [text] = plain.session.frames_to_send()
    assert not text.binary
    assert json.loads(text.data) == {"op": "publish", "topic": "/c", "msg": {"data": "hi"}}
    assert decoded(cbor) == [{"op": "publish", "topic": "/c", "msg": {"data": "hi"}}]
    [message] = decoded(raw)
    assert message["msg"]["bytes"] == b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00"


def test_png_subscription_gets_the_reference_png_op(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/c", type="std_msgs/String", compression="png")
    pub.send(op="publish", topic="/c", msg={"data": "compress me"})
    [frame] = decoded(sub)
    assert set(frame) == {"op", "data"} and frame["op"] == "png"
    text = decode_png(str(frame["data"]), max_bytes=1 << 20)
    assert json.loads(text) == {"op": "publish", "topic": "/c", "msg": {"data": "compress me"}}


def test_png_above_the_fragment_size_is_split_into_png_parts(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    sub.send(
        op="subscribe", topic="/c", type="std_msgs/String", compression="png", fragment_size=40
    )
    pub.send(op="publish", topic="/c", msg={"data": "x" * 500})
    frames = decoded(sub)
    assert len(frames) > 1
    assert {f["op"] for f in frames} == {"png"}
    assert [f["num"] for f in frames] == list(range(len(frames)))
    assert all(f["total"] == len(frames) and len(str(f["data"])) <= 40 for f in frames)
    assert len({f["id"] for f in frames}) == 1
    assert reassemble(frames) == [{"op": "publish", "topic": "/c", "msg": {"data": "x" * 500}}]


def test_png_is_deflated_off_the_loop_in_order_and_a_backlog_keeps_every_message(
    graph: Graph, pub: Peer
) -> None:
    """With a transport that runs jobs, a png message is a background job (pngout):
    a subscriber's messages in order, however many wait within its send buffer limit."""
    sub = Peer(graph, "sub")
    sub.session.jobs.transport_runs = True  # as the connection runtime does
    sub.send(op="subscribe", topic="/c", type="std_msgs/String", compression="png")
    for n in range(100):  # faster than the worker takes them
        pub.send(op="publish", topic="/c", msg={"data": str(n)})
    assert sub.session.frames_to_send() == []  # nothing deflated on the loop
    assert sub.session.stats.pending_bytes >= 100 * pngout_cost("0")
    while (job := sub.session.jobs.take_background()) is not None:
        sub.session.finish_job(job, job.run(), 0.0)
    texts = [json.loads(decode_png(str(f["data"]), max_bytes=1 << 20)) for f in decoded(sub)]
    assert [t["msg"]["data"] for t in texts] == [str(n) for n in range(100)]
    assert sub.session.stats.dropped_frames == 0 and sub.session.stats.pending_bytes == 0
    pub.send(op="publish", topic="/c", msg={"data": "late"})
    job = sub.session.jobs.take_background()
    assert job is not None
    sub.send(op="unsubscribe", topic="/c")  # gone while its message was deflated
    sub.session.finish_job(job, job.run(), 0.0)
    assert decoded(sub) == []


def pngout_cost(data: str) -> int:
    """What a waiting png message of ``/c`` with ``data`` is charged (pngout)."""
    text = json.dumps({"op": "publish", "topic": "/c", "msg": {"data": data}})
    return len(text.replace(" ", "")) + FRAME_OVERHEAD_BYTES


def test_png_backlog_past_the_send_buffer_limit_loses_its_oldest(graph: Graph, pub: Peer) -> None:
    """The waiting png messages count with the outbox: past --send-buffer-limit the oldest
    topic messages go (D24), queued ones first, and the peer is told once."""
    limit = 20 * pngout_cost("00")
    session = Session(
        graph.port,
        "sub",
        config=SessionConfig(send_buffer_limit=limit, status_level=StatusLevel.WARNING),
    )
    session.jobs.transport_runs = True
    session.receive_frame(
        json.dumps(
            {"op": "subscribe", "topic": "/c", "type": "std_msgs/String", "compression": "png"}
        ),
        0.0,
    )
    for n in range(50):
        pub.send(op="publish", topic="/c", msg={"data": f"{n:02}"})
    assert session.stats.queued_bytes + session.stats.pending_bytes <= limit
    while (job := session.jobs.take_background()) is not None:
        session.finish_job(job, job.run(), 0.0)
    frames = [json.loads(f.data) for f in session.frames_to_send()]
    texts = [
        json.loads(decode_png(str(f["data"]), max_bytes=1 << 20))
        for f in frames
        if f["op"] == "png"
    ]
    got = [t["msg"]["data"] for t in texts]
    assert got == [f"{n:02}" for n in range(50 - len(got), 50)] and 10 < len(got) <= 20
    assert session.stats.dropped_frames == 50 - len(got)
    warnings = [f["msg"] for f in frames if f["op"] == "status"]
    assert len(warnings) == 1 and "dropping the oldest topic messages" in warnings[0]


def test_json_above_the_fragment_size_is_fragmented_with_fresh_ids(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/c", type="std_msgs/String", fragment_size=60)
    pub.send(op="publish", topic="/c", msg={"data": "y" * 100})
    pub.send(op="publish", topic="/c", msg={"data": "short"})
    pub.send(op="publish", topic="/c", msg={"data": "z" * 100})
    frames = decoded(sub)
    assert frames[3] == {"op": "publish", "topic": "/c", "msg": {"data": "short"}}
    fragments = [f for f in frames if f["op"] == "fragment"]
    assert all(len(str(f["data"])) <= 60 and isinstance(f["total"], int) for f in fragments)
    assert len({f["id"] for f in fragments}) == 2
    assert [m["msg"] for m in reassemble(frames)] == [
        {"data": "y" * 100},
        {"data": "short"},
        {"data": "z" * 100},
    ]


def test_fragment_size_counts_characters_not_bytes(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    text = {"op": "publish", "topic": "/c", "msg": {"data": "\u00e9" * 10}}
    size = len(json.dumps(text, ensure_ascii=False, separators=(",", ":")))
    sub.send(op="subscribe", topic="/c", type="std_msgs/String", fragment_size=size)
    pub.send(op="publish", topic="/c", msg={"data": "\u00e9" * 10})
    assert decoded(sub) == [text]


def test_cbor_is_never_fragmented(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    sub.send(
        op="subscribe", topic="/c", type="std_msgs/String", compression="cbor", fragment_size=5
    )
    pub.send(op="publish", topic="/c", msg={"data": "x" * 100})
    assert decoded(sub) == [{"op": "publish", "topic": "/c", "msg": {"data": "x" * 100}}]


def test_one_serialization_per_distinct_encoding(
    graph: Graph, pub: Peer, monkeypatch: pytest.MonkeyPatch
) -> None:
    counts = {"json": 0, "cbor": 0, "png": 0, "raw": 0, "typed": 0}
    events: list[MessageEvent] = []

    def counting(name: str, real):  # type: ignore[no-untyped-def]
        def wrapper(*args, **kwargs):  # type: ignore[no-untyped-def]
            counts[name] += 1
            return real(*args, **kwargs)

        return wrapper

    monkeypatch.setattr(encoding, "encode_cbor", counting("cbor", encoding.encode_cbor))
    monkeypatch.setattr(encoding, "encode_png", counting("png", encoding.encode_png))
    monkeypatch.setattr(
        encoding, "encode_publish_json", counting("json", encoding.encode_publish_json)
    )
    codec = codec_for(graph.registry, graph.registry.message("std_msgs/Float64MultiArray"))
    monkeypatch.setattr(codec, "serialize", counting("raw", codec.serialize))
    monkeypatch.setattr(codec, "typed", counting("typed", codec.typed))

    graph.port.subscribe("probe", "/m", "std_msgs/Float64MultiArray", _Probe(events))
    groups = {"none": 3, "cbor": 2, "cbor-raw": 2, "png": 3}
    peers = {c: [Peer(graph, f"{c}{i}") for i in range(n)] for c, n in groups.items()}
    for compression, members in peers.items():
        for peer in members:
            peer.send(op="subscribe", topic="/m", compression=compression)
    pub.send(op="publish", topic="/m", msg={"data": [1.0, 2.0]})

    [event] = events
    assert event.encodings_made == 4
    # The publish op goes to JSON once: PNG compresses that same text.
    assert counts == {"json": 1, "cbor": 2, "png": 1, "raw": 1, "typed": 1}
    for members in peers.values():
        frames = [peer.session.frames_to_send() for peer in members]
        assert all(len(f) == 1 and f[0] is frames[0][0] for f in frames)


class _Probe:
    def __init__(self, events: list[MessageEvent]) -> None:
        self.events = events

    def on_message(self, event: MessageEvent) -> None:
        self.events.append(event)


def test_spellings_and_fragment_sizes_are_distinct_forms(graph: Graph, pub: Peer) -> None:
    events: list[MessageEvent] = []
    graph.port.subscribe("probe", "/c", "std_msgs/String", _Probe(events))
    for i, (topic, size) in enumerate([("c", None), ("/c", None), ("/c", 10), ("/c", 10)]):
        Peer(graph, f"s{i}").send(op="subscribe", topic=topic, fragment_size=size)
    pub.send(op="publish", topic="/c", msg={"data": "spelled"})
    assert events[0].encodings_made == 3


def test_incoming_fragments_of_any_op_in_any_order(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/c", type="std_msgs/String")
    text = json.dumps({"op": "publish", "topic": "/c", "msg": {"data": "in parts"}, "id": "p"})
    frames = [json.loads(f) for f in _fragment(text, 7, "f1")]
    for frame in reversed(frames):
        pub.send(**frame)
    assert decoded(sub) == [{"op": "publish", "topic": "/c", "msg": {"data": "in parts"}}]
    assert pub.received() == []
    assert len(pub.session.fragments) == 0


def _fragment(text: str, size: int, op_id: str, op: str = "fragment") -> list[bytes]:
    return fragment_frames(text, op_id, size, op=op)


def test_a_fragmented_call_service_gets_its_reply(pub: Peer) -> None:
    text = json.dumps({"op": "call_service", "service": "/s", "id": "call-1"})
    for frame in _fragment(text, 10, "frag-1"):
        pub.send_raw(frame)
    replies = [m for m in pub.received() if m["op"] == "service_response"]
    assert [r["id"] for r in replies] == ["call-1"]


def test_bad_fragments_get_an_error_status_with_their_id(pub: Peer) -> None:
    pub.send(op="fragment", id="m", data="{", num=0, total=2)
    pub.send(op="fragment", id="m", data="{", num=0, total=2)
    pub.send(op="fragment", id="m", data="}", num=1, total=3)
    pub.send(op="fragment", id="m", data="x", num=2, total=2)
    pub.send(op="fragment", id="m", data="x", num=1, total=2.5)
    statuses = pub.statuses()
    assert [s["id"] for s in statuses] == ["m"] * 4
    assert [s["level"] for s in statuses] == ["error"] * 4
    texts = [str(s["msg"]) for s in statuses]
    assert texts[0] == "fragment: duplicate part 0 of id 'm'"
    assert "total 3 differs from 2" in texts[1]
    assert "num 2 is not below total 2" in texts[2]
    assert "$.total" in texts[3]
    pub.send(op="fragment", id="m", data="}", num=1, total=2)
    [status] = pub.statuses()
    assert status["msg"] == "missing field at $.op"  # the reassembled "{}" is processed


def test_incomplete_fragments_expire_on_the_session_timer(graph: Graph, clock: FakeClock) -> None:
    woken: list[int] = []
    session = Session(
        graph.port,
        "c",
        config=SessionConfig(fragment_timeout_s=5.0),
        on_output=lambda: woken.append(1),
    )
    session.receive_frame(b'{"op":"fragment","id":"late","data":"{","num":0,"total":2}', clock.now)
    assert woken and session.get_timer() == clock.now + 5.0
    assert session.fragments.held_bytes > 0
    session.handle_timer(clock.now + 4.9)
    assert session.frames_to_send() == []
    session.handle_timer(clock.now + 5.0)
    [status] = [json.loads(f.data) for f in session.frames_to_send()]
    assert status["id"] == "late" and status["level"] == "error"
    assert status["msg"] == "fragment: message 'late' dropped incomplete after 5 s (1 of 2 parts)"
    assert session.fragments.held_bytes == 0 and session.get_timer() is None


def test_pending_fragments_are_bounded_and_freed_on_close(graph: Graph, clock: FakeClock) -> None:
    config = SessionConfig(max_pending_fragments=2, max_message_size=1000)
    session = Session(graph.port, "c", config=config)
    for name in ("a", "b", "c"):
        frame = {"op": "fragment", "id": name, "data": "x", "num": 0, "total": 9}
        session.receive_frame(json.dumps(frame), clock.now)
    big = {"op": "fragment", "id": "a", "data": "x" * 2000, "num": 1, "total": 9}
    session.receive_frame(json.dumps(big), clock.now)
    messages = [json.loads(f.data)["msg"] for f in session.frames_to_send()]
    assert "too many incomplete messages (limit 2)" in messages[0]
    assert "'a' dropped" in messages[1]
    assert len(session.fragments) == 1
    session.close()
    assert len(session.fragments) == 0 and session.fragments.held_bytes == 0


def test_png_ops_are_decoded_whole_in_parts_and_inside_fragments(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/c", type="std_msgs/String")

    def op(data: str) -> bytes:
        return msgspec.json.encode({"op": "publish", "topic": "/c", "msg": {"data": data}})

    pub.send(op="png", data=encode_png(op("whole")))
    for frame in reversed(_fragment(encode_png(op("parts")), 16, "p", op="png")):
        pub.send_raw(frame)
    png_op = json.dumps({"op": "png", "data": encode_png(op("nested"))})
    for frame in _fragment(png_op, 20, "outer"):
        pub.send_raw(frame)
    assert [m["msg"] for m in decoded(sub)] == [
        {"data": "whole"},
        {"data": "parts"},
        {"data": "nested"},
    ]
    assert pub.received() == []


def test_bad_png_ops_get_an_error_status(pub: Peer) -> None:
    pub.send(op="png", data="%%%", id=1)
    pub.send(op="png", data="AAAA", id=2, num=0)
    pub.send(op="png", data=base64.b64encode(b"not a png").decode(), id=3)
    statuses = pub.statuses()
    assert [(s["id"], s["level"]) for s in statuses] == [(1, "error"), (2, "error"), (3, "error")]
    assert [str(s["msg"]) for s in statuses] == [
        "png: data is not valid base64",
        "png: id, num and total must be given together",
        "png: data is not a valid PNG image",
    ]


def test_binary_frames_are_cbor_ops(graph: Graph, pub: Peer) -> None:
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/img", type="sensor_msgs/Image")
    msg = {"height": 1, "width": 2, "encoding": "mono8", "step": 2, "data": b"\x07\x08"}
    frame = cbor2.dumps({"op": "publish", "topic": "/img", "msg": msg})
    pub.session.receive_frame(frame, 0.0, binary=True)
    [message] = decoded(sub)
    assert base64.b64decode(message["msg"]["data"]) == b"\x07\x08"
    floats = cbor2.dumps(
        {
            "op": "publish",
            "topic": "/f",
            "msg": {"data": cbor2.CBORTag(85, np.array([0.5], "<f4").tobytes())},
        }
    )
    sub.send(op="subscribe", topic="/f", type="std_msgs/Float32MultiArray")
    pub.session.receive_frame(floats, 0.0, binary=True)
    assert [m["msg"]["data"] for m in decoded(sub) if m["op"] == "publish"] == [[0.5]]


@pytest.mark.parametrize(
    ("frame", "text"),
    [
        (cbor2.dumps([1, 2]), "expected a JSON object, got array"),
        (b"\xff\xff", "invalid CBOR"),
        (json.dumps({"op": "status"}).encode(), "invalid CBOR"),
    ],
)
def test_bad_binary_frames_get_an_error_status(pub: Peer, frame: bytes, text: str) -> None:
    pub.session.receive_frame(frame, 0.0, binary=True)
    [status] = pub.statuses()
    assert text in str(status["msg"])


def test_replies_take_their_requested_encoding(graph: Graph, pub: Peer) -> None:
    codec = codec_for(graph.registry, graph.registry.message("std_msgs/Int16MultiArray"))
    reply: dict[str, object] = {
        "op": "service_response",
        "service": "/s",
        "values": {"layout": {"dim": [], "data_offset": 0}, "data": [1, -1]},
        "result": True,
        "id": "call:1",
    }
    op = ServiceResponse(service="/s", values=reply["values"], result=True, id="call:1")
    session = pub.session
    session.send(op, compression=Compression.CBOR, codec=codec)
    session.send(op, compression=Compression.CBOR)
    session.send(op, compression=Compression.PNG)
    session.send(op, fragment_size=25)
    session.send(op.model_copy(update={"id": None}), compression=Compression.PNG, fragment_size=50)
    frames = session.frames_to_send()
    assert not any(f.droppable for f in frames)
    typed, plain = cbor2.loads(frames[0].data), cbor2.loads(frames[1].data)
    assert frames[0].binary and typed["values"]["data"] == cbor2.CBORTag(77, b"\x01\x00\xff\xff")
    assert plain["values"]["data"] == [1, -1]
    text = [json.loads(f.data) for f in frames[2:]]
    assert text[0]["op"] == "png"
    fragments = [t for t in text if t["op"] == "fragment"]
    assert {f["id"] for f in fragments} == {"call:1"}
    parts = [t for t in text[1:] if t["op"] == "png"]
    assert len({p["id"] for p in parts}) == 1 and str(parts[0]["id"]).startswith("rwt:")
    no_id = {key: value for key, value in reply.items() if key != "id"}
    assert reassemble(text) == [reply, reply, no_id]


def test_fragments_of_a_message_are_dropped_together() -> None:
    box = Outbox(limit_bytes=10, frame_overhead_bytes=0)  # payload sizes only
    group = object()
    box.push(OutFrame(b"ssss"))
    box.extend([OutFrame(part, droppable=True, group=group) for part in (b"aa", b"bb", b"cc")])
    box.push(OutFrame(b"dddd", droppable=True))
    assert [f.data for f in box.drain()] == [b"ssss", b"dddd"]
    assert box.dropped == 1


def test_status_stays_json_on_a_cbor_subscription(graph: Graph) -> None:
    sub = Peer(graph, "sub", StatusLevel.INFO)
    sub.send(op="subscribe", topic="/c", type="std_msgs/String", compression="cbor", id="s")
    [frame] = sub.session.frames_to_send()
    assert not frame.binary and json.loads(frame.data)["op"] == "status"


def test_cbor_types_arrays_inside_nested_messages_and_message_arrays(
    graph: Graph, pub: Peer
) -> None:
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/odom", type="nav_msgs/Odometry", compression="cbor")
    sub.send(op="subscribe", topic="/cloud", type="sensor_msgs/PointCloud", compression="cbor")
    pub.send(op="publish", topic="/odom", msg={"pose": {"covariance": [0.5] * 36}})
    channels = [{"name": "i", "values": [1.0, 2.0]}, {"name": "j", "values": []}]
    pub.send(op="publish", topic="/cloud", msg={"channels": channels})
    odom, cloud = decoded(sub)
    covariance = odom["msg"]["pose"]["covariance"]
    assert covariance == cbor2.CBORTag(86, np.full(36, 0.5, "<f8").tobytes())
    assert odom["msg"]["twist"]["covariance"].tag == 86
    assert [c["values"] for c in cloud["msg"]["channels"]] == [
        cbor2.CBORTag(85, np.array([1.0, 2.0], "<f4").tobytes()),
        cbor2.CBORTag(85, b""),
    ]
    assert cloud["msg"]["points"] == []


def test_a_failure_reply_stays_plain_with_a_codec(graph: Graph, pub: Peer) -> None:
    codec = codec_for(graph.registry, graph.registry.message("std_msgs/Int16MultiArray"))
    failure = ServiceResponse(service="/s", values="no", result=False)
    pub.session.send(failure, compression=Compression.CBOR, codec=codec)
    assert decoded(pub) == [
        {"op": "service_response", "service": "/s", "result": False, "values": "no"}
    ]


def test_a_message_that_cannot_be_encoded_is_reported_to_its_subscriber_only(
    graph: Graph, pub: Peer, monkeypatch: pytest.MonkeyPatch
) -> None:
    codec = codec_for(graph.registry, graph.registry.message("std_msgs/String"))

    def broken(msg: object) -> bytes:
        raise KeyError("std_msgs/msg/String")

    monkeypatch.setattr(codec, "serialize", broken)
    raw, plain = Peer(graph, "raw"), Peer(graph, "plain")
    raw.send(op="subscribe", topic="/c", type="std_msgs/String", compression="cbor-raw")
    plain.send(op="subscribe", topic="/c", type="std_msgs/String")
    pub.send(op="publish", topic="/c", msg={"data": "x"}, id="p")
    [status] = raw.received()
    assert status == {
        "op": "status",
        "level": "error",
        "msg": "subscribe: cannot send a message of /c as cbor-raw",
    }
    assert plain.received() == [{"op": "publish", "topic": "/c", "msg": {"data": "x"}}]
    assert pub.received() == []


def test_cbor_raw_without_a_codec_falls_back_to_cbor() -> None:
    event = MessageEvent("/c", "std_msgs/msg/String", {"data": "x"}, 0.0)
    [frame] = encoding.publish_frames(event, "/c", "cbor-raw", None)
    assert frame.binary and cbor2.loads(frame.data)["msg"] == {"data": "x"}


@settings(max_examples=60, deadline=None)
@given(text=st.text(max_size=300), size=st.integers(1, 80), data=st.data())
def test_any_fragmenting_of_a_publish_delivers_it_once(
    text: str, size: int, data: st.DataObject
) -> None:
    graph = Graph(clock=FakeClock())
    pub, sub = Peer(graph, "pub"), Peer(graph, "sub")
    sub.send(op="subscribe", topic="/c", type="std_msgs/String")
    op = json.dumps({"op": "publish", "topic": "/c", "msg": {"data": text}})
    frames = data.draw(st.permutations(fragment_frames(op, "m", size)))
    for frame in frames:
        pub.send_raw(frame)
    assert decoded(sub) == [{"op": "publish", "topic": "/c", "msg": {"data": text}}]
    assert pub.received() == [] and pub.session.fragments.held_bytes == 0


def test_a_closed_session_sends_nothing_and_frees_its_parts(graph: Graph, clock: FakeClock) -> None:
    woken: list[int] = []
    session = Session(graph.port, "c", on_output=lambda: woken.append(1))
    part = {"op": "fragment", "id": "x", "data": "{", "num": 0, "total": 2}
    session.receive_frame(cbor2.dumps(part), clock.now, binary=True)
    assert len(session.fragments) == 1 and woken == [1]  # the expiry timer
    session.send_frames([OutFrame(b"{}")])
    assert [f.data for f in session.frames_to_send()] == [b"{}"]
    session.close()
    session.receive_frame(json.dumps({**part, "id": "y"}), clock.now)
    session.send_frames([OutFrame(b"{}")])
    session.call_at(clock.now + 1, lambda now: None)
    assert session.frames_to_send() == [] and len(session.fragments) == 0
    assert woken == [1, 1] and session.get_timer() is None
