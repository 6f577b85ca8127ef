"""The CBOR codec (spec 3.1.3, D21, D27, REF §3.2)."""

from __future__ import annotations

import cbor2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from rwt_protocol.codecs import cbor as codec_cbor
from rwt_protocol.codecs.cbor import TYPED_ARRAY_TAGS, decode_cbor, encode_cbor
from rwt_protocol.errors import RemoteProtocolError

INTS = {
    "int8": (-(2**7), 2**7 - 1),
    "uint16": (0, 2**16 - 1),
    "uint32": (0, 2**32 - 1),
    "uint64": (0, 2**64 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "int64": (-(2**63), 2**63 - 1),
}


def _values(dtype: str) -> st.SearchStrategy[list[object]]:
    if dtype in INTS:
        low, high = INTS[dtype]
        return st.lists(st.integers(low, high), max_size=40)
    width = 32 if dtype == "float32" else 64
    return st.lists(st.floats(width=width, allow_nan=False), max_size=40)


@pytest.mark.parametrize("dtype", sorted(set(TYPED_ARRAY_TAGS) - {"uint8"}))
@given(data=st.data())
def test_typed_array_round_trip_for_every_numeric_type(dtype: str, data: st.DataObject) -> None:
    values = data.draw(_values(dtype))
    frame = encode_cbor({"op": "publish", "msg": {"data": np.asarray(values, dtype=dtype)}})
    tag = cbor2.loads(frame)["msg"]["data"]
    assert isinstance(tag, cbor2.CBORTag)
    assert tag.tag == TYPED_ARRAY_TAGS[dtype]
    assert tag.value == np.asarray(values, dtype=np.dtype(dtype).newbyteorder("<")).tobytes()
    assert decode_cbor(frame) == {"op": "publish", "msg": {"data": values}}


@given(values=st.binary(max_size=100))
def test_uint8_arrays_are_plain_byte_strings(values: bytes) -> None:
    array = np.frombuffer(values, dtype=np.uint8)
    frame = encode_cbor({"bytes": values, "array": array})
    assert cbor2.loads(frame) == {"bytes": values, "array": values}


def test_big_endian_input_is_packed_little_endian() -> None:
    frame = encode_cbor({"a": np.array([1, 2], dtype=">i4")})
    assert cbor2.loads(frame)["a"] == cbor2.CBORTag(78, b"\x01\x00\x00\x00\x02\x00\x00\x00")


def test_bools_floats_times_and_strings_keep_their_cbor_types() -> None:
    msg = {
        "flags": np.array([True, False]),
        "x": 1.5,
        "stamp": {"sec": 3, "nanosec": 4},
        "names": ["a", "b"],
        "nan": float("nan"),
    }
    frame = encode_cbor(msg)
    assert b"\xfb\x3f\xf8\x00\x00\x00\x00\x00\x00" in frame  # 1.5 as a float64
    decoded = cbor2.loads(frame)
    assert decoded["flags"] == [True, False]
    assert decoded["stamp"] == {"sec": 3, "nanosec": 4}
    assert decoded["names"] == ["a", "b"]
    assert decoded["nan"] != decoded["nan"]


def test_values_without_a_cbor_form_are_a_bug() -> None:
    with pytest.raises(TypeError):
        encode_cbor({"x": object()})


def test_client_typed_arrays_decode_big_endian_too() -> None:
    frame = cbor2.dumps(
        {"a": cbor2.CBORTag(74, b"\x00\x00\x00\x01"), "b": cbor2.CBORTag(64, b"\x05")}
    )
    assert decode_cbor(frame) == {"a": [1], "b": [5]}


@pytest.mark.parametrize(
    ("frame", "text"),
    [
        (b"", "invalid CBOR"),
        (b"\xff", "invalid CBOR"),
        (b"\xa0\x00", "bytes after the first data item"),
        (b"\x81" * 1000, "nesting deeper than 100"),
        (bytes.fromhex("c640"), "unsupported CBOR tag 6"),
        (bytes.fromhex("d84e4100"), "partial element"),
        (bytes.fromhex("d84e01"), "unsupported CBOR tag 78"),
        (bytes.fromhex("d81c81d81d00"), "shared values"),
        (bytes.fromhex("5bffffffffffffffff"), "invalid CBOR"),
    ],
)
def test_bad_cbor_is_a_remote_error(frame: bytes, text: str) -> None:
    with pytest.raises(RemoteProtocolError, match=text):
        decode_cbor(frame)


@pytest.fixture
def splicing(monkeypatch: pytest.MonkeyPatch) -> None:
    """The splicer on whatever ``RWT_NO_SHORTCUTS`` says: these tests compare it with cbor2."""
    monkeypatch.setattr(codec_cbor, "_SPLICE_ENCODE", True)
    monkeypatch.setattr(codec_cbor, "_SPLICE_DECODE", True)


def _plain(value: object) -> bytes:
    """What cbor2 makes of an op on its own (the reference for spliced frames)."""
    from rwt_protocol.codecs.cbor import _encode_array  # noqa: PLC0415

    return cbor2.dumps(value, default=_encode_array)


@pytest.mark.usefixtures("splicing")
@pytest.mark.parametrize("size", [65535, 65536, 70000, 2**24 + 3])
@pytest.mark.parametrize("dtype", ["uint8", "int8", ">i4", "<f4", "float64", "uint64"])
def test_large_payloads_are_spliced_into_the_same_bytes(size: int, dtype: str) -> None:
    array = np.arange(size // np.dtype(dtype).itemsize).astype(dtype)
    msg = {"header": {"frame_id": "cam"}, "data": array, "raw": bytes(size), "n": list(range(30))}
    op = {"op": "publish", "topic": "/big", "msg": msg, **{f"k{i}": i for i in range(25)}}
    frame = encode_cbor(op)
    assert frame == _plain(op)
    decoded = decode_cbor(frame, typed_arrays=True)
    data = decoded["msg"]["data"]  # type: ignore[index]
    if array.dtype == np.uint8:  # uint8 arrays travel as plain byte strings (REF §3.2)
        data = np.frombuffer(data, np.uint8)
    assert np.array_equal(data, array)
    assert decoded["msg"]["raw"] == bytes(size)  # type: ignore[index]


@pytest.mark.usefixtures("splicing")
def test_payloads_deeper_than_the_splice_levels_are_encoded_too() -> None:
    op = {"op": "publish", "msg": {"a": {"b": {"data": bytes(70000)}}, "blob": bytes(70000)}}
    assert encode_cbor(op) == _plain(op)


@pytest.mark.usefixtures("splicing")
@pytest.mark.parametrize("typed", [True, False])
@pytest.mark.parametrize("dtype", ["uint8", "int8", ">i4", "<f4", "float64"])
def test_large_frames_decode_alike_through_the_splicer(typed: bool, dtype: str) -> None:
    array = np.arange(70000).astype(dtype)
    tag = {"uint8": 64, "int8": 72, ">i4": 74, "<f4": 85, "float64": 86}[dtype]
    msg = {"header": {"frame_id": "cam", "stamp": {"sec": 1}}, "n": [1, 2.5, None, True]}
    op = {
        "op": "publish",
        "topic": "/big",
        "msg": {**msg, "data": cbor2.CBORTag(tag, array.tobytes()), "raw": bytes(70000)},
    }
    got = decode_cbor(cbor2.dumps(op), typed_arrays=typed)
    data = got["msg"].pop("data")  # type: ignore[index, union-attr]
    assert got == {"op": "publish", "topic": "/big", "msg": {**msg, "raw": bytes(70000)}}
    assert isinstance(data, np.ndarray) is typed
    assert np.array_equal(np.asarray(data), array)


@pytest.mark.usefixtures("splicing")
@pytest.mark.parametrize(
    ("frame", "text"),
    [
        (cbor2.dumps({"msg": {"data": bytes(70000)}})[:-5], "invalid CBOR"),  # cut short
        (cbor2.dumps({"msg": {"data": bytes(70000)}}) + b"\x00", "bytes after the first"),
        (cbor2.dumps({"msg": {"d": cbor2.CBORTag(77, bytes(70001))}}), "partial element"),
        (cbor2.dumps({"msg": {"d": cbor2.CBORTag(99, bytes(70000))}}), "unsupported CBOR tag 99"),
    ],
)
def test_large_bad_frames_are_refused(frame: bytes, text: str) -> None:
    with pytest.raises(RemoteProtocolError, match=text):
        decode_cbor(frame, typed_arrays=True)


@pytest.mark.usefixtures("splicing")
def test_a_large_byte_view_is_spliced_as_a_byte_string() -> None:
    data = bytes(range(256)) * 300
    view = memoryview(bytearray(data)).toreadonly()  # what rosbags' serializer returns
    frame = encode_cbor({"op": "publish", "msg": {"secs": 1, "nsecs": 2, "bytes": view}})
    assert frame == cbor2.dumps({"op": "publish", "msg": {"secs": 1, "nsecs": 2, "bytes": data}})
