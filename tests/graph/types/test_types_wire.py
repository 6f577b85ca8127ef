"""The message codec for CBOR and cbor-raw (D21, REF §3.2, §3.5).

Property: for every primitive array type (unbounded, fixed and bounded), a
message goes through ``WireCodec.typed`` and the CBOR encoder and comes back,
decoded by rwt's own CBOR decoder, equal to the internal form; the typed-array
tags are REF §3.2's. ``serialize`` agrees with rosbags' deserializer.
"""

from __future__ import annotations

from pathlib import Path

import cbor2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rwt_graph.types import Dialect, MessageType, TypeRegistry, codec_for
from rwt_protocol.codecs.cbor import decode_cbor, encode_cbor

ARRAYS = """\
bool[] b
byte[] y
char[] c
int8[] i8
uint8[] u8
int16[] i16
uint16[] u16
int32[] i32
uint32[] u32
int64[] i64
uint64[] u64
float32[] f32
float64[] f64
string[] s
float32[3] fixed
int16[<=4] bounded
builtin_interfaces/Time[] times
"""

TAGS = {
    "i8": 72,
    "i16": 77,
    "u16": 69,
    "i32": 78,
    "u32": 70,
    "i64": 79,
    "u64": 71,
    "f32": 85,
    "f64": 86,
    "fixed": 85,
    "bounded": 77,
}


@pytest.fixture(scope="module")
def arrays(tmp_path_factory: pytest.TempPathFactory) -> tuple[TypeRegistry, MessageType]:
    root = tmp_path_factory.mktemp("interfaces")
    folder = root / "wire_msgs" / "msg"
    folder.mkdir(parents=True)
    (folder / "Arrays.msg").write_text(ARRAYS)
    registry = TypeRegistry(Dialect.ROS2, [Path(root)])
    return registry, registry.message("wire_msgs/Arrays")


def ints(bits: int, signed: bool) -> st.SearchStrategy[int]:
    if signed:
        return st.integers(-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    return st.integers(0, 2**bits - 1)


f32 = st.floats(width=32, allow_nan=False)
messages = st.fixed_dictionaries(
    {
        "b": st.lists(st.booleans(), max_size=8),
        "y": st.lists(ints(8, False), max_size=8),
        "c": st.binary(max_size=8),
        "i8": st.lists(ints(8, True), max_size=8),
        "u8": st.binary(max_size=8),
        "i16": st.lists(ints(16, True), max_size=8),
        "u16": st.lists(ints(16, False), max_size=8),
        "i32": st.lists(ints(32, True), max_size=8),
        "u32": st.lists(ints(32, False), max_size=8),
        "i64": st.lists(ints(64, True), max_size=8),
        "u64": st.lists(ints(64, False), max_size=8),
        "f32": st.lists(f32, max_size=8),
        "f64": st.lists(st.floats(allow_nan=False), max_size=8),
        "s": st.lists(st.text(max_size=5), max_size=4),
        "fixed": st.lists(f32, min_size=3, max_size=3),
        "bounded": st.lists(ints(16, True), max_size=4),
        "times": st.lists(
            st.fixed_dictionaries({"sec": ints(32, True), "nanosec": ints(32, False)}),
            max_size=3,
        ),
    }
)


@settings(max_examples=60, deadline=None)
@given(value=messages)
def test_cbor_round_trip_of_every_primitive_array_type(
    arrays: tuple[TypeRegistry, MessageType], value: dict[str, object]
) -> None:
    registry, mtype = arrays
    msg = mtype.from_json(value, now=0.0).msg
    frame = encode_cbor(
        {"op": "publish", "topic": "/a", "msg": codec_for(registry, mtype).typed(msg)}
    )
    decoded = decode_cbor(frame)
    assert isinstance(decoded, dict)
    # ROS 2 byte[] (octets) travels as a byte string, like uint8[] (REF §3.2).
    assert decoded["msg"] == {**msg, "y": bytes(msg["y"])}  # type: ignore[call-overload]
    # What a CBOR client receives, it can publish back unchanged (D21).
    assert mtype.from_json(decoded["msg"], now=0.0).msg == msg
    raw = cbor2.loads(frame)["msg"]
    for name, tag in TAGS.items():
        assert raw[name].tag == tag, name
    for name in ("y", "c", "u8"):
        assert isinstance(raw[name], bytes), name  # uint8 arrays: plain byte strings
    assert raw["b"] == msg["b"] and raw["s"] == msg["s"] and raw["times"] == msg["times"]


def test_typed_leaves_types_without_numeric_arrays_alone() -> None:
    registry = TypeRegistry()
    mtype = registry.message("std_msgs/String")
    msg = {"data": "x"}
    assert codec_for(registry, mtype).typed(msg) is msg
    assert codec_for(registry, mtype) is codec_for(registry, mtype)


@settings(max_examples=25, deadline=None)
@given(value=messages)
def test_serialize_is_cdr_that_rosbags_reads_back(
    arrays: tuple[TypeRegistry, MessageType], value: dict[str, object]
) -> None:
    registry, mtype = arrays
    msg = mtype.from_json(value, now=0.0).msg
    raw = codec_for(registry, mtype).serialize(msg)
    assert raw[:4] == b"\x00\x01\x00\x00"
    store = registry.typestore()
    assert mtype.from_python(store.deserialize_cdr(raw, mtype.rosbags_name)) == msg
