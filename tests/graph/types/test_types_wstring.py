"""A ROS 2 ``wstring`` in CDR is rmw's: its UTF-16 code units, each a uint32 (docs/ros2.md).

rmw_fastrtps writes a ``wstring`` as a ``sequence<uint32>``: the count of UTF-16
code units, then each unit in 4 bytes, no terminator; a character outside the
BMP is a surrogate pair. tests/foxglove/test_cdr_every_type.py compares this
with rclpy's own bytes; here the bytes are pinned without rclpy, and a peer's
bytes that are no such wstring are refused with ``CdrError``.
"""

from __future__ import annotations

import pytest
from types_support import DATA

from rwt_graph.types import Dialect, MessageType, TypeRegistry
from rwt_graph.types.interop import from_rosbags, to_rosbags
from rwt_graph.types.wire import CdrError, read_cdr

WIDE = "rwt_test_msgs/Wide"
VALUE = {"before": 1, "plain": "hé😀", "fixed": ["a", ""], "few": ["😀"], "after": 2}
# header; before and 3 bytes of padding; plain: 4 units, h é and the emoji's surrogate pair;
# bounded: empty; fixed: "a" and ""; few: one wstring of 2 units; many: none; after
PINNED = bytes.fromhex(
    "00010000"
    "01000000"
    "04000000"
    "68000000"
    "e9000000"
    "3dd80000"
    "00de0000"
    "00000000"
    "01000000"
    "61000000"
    "00000000"
    "01000000"
    "02000000"
    "3dd80000"
    "00de0000"
    "00000000"
    "02"
)


@pytest.fixture(scope="module")
def registry() -> TypeRegistry:
    return TypeRegistry(Dialect.ROS2, [DATA])


@pytest.fixture(scope="module")
def wide(registry: TypeRegistry) -> MessageType:
    return registry.message(WIDE)


def _decode(registry: TypeRegistry, mtype: MessageType, data: bytes) -> dict[str, object]:
    return mtype.from_python(read_cdr(registry.typestore(), data, mtype.rosbags_name))


def test_wstrings_are_utf16_code_units_in_four_bytes(
    registry: TypeRegistry, wide: MessageType
) -> None:
    msg = wide.from_json(VALUE, now=0.0).msg
    assert registry.serialize(wide, msg) == PINNED
    store = registry.typestore()
    general = to_rosbags(msg, wide, store, registry.message)
    assert bytes(store.serialize_cdr(general, wide.rosbags_name)) == PINNED
    back = _decode(registry, wide, PINNED)
    assert back == {**VALUE, "bounded": "", "many": []}
    obj = read_cdr(store, PINNED, wide.rosbags_name)
    assert from_rosbags(obj, wide, registry.message) == wide.plain_from_rosbags(obj)


def test_a_lone_surrogate_a_client_sent_goes_out_as_its_code_unit(
    registry: TypeRegistry, wide: MessageType
) -> None:
    msg = wide.from_json({"plain": "\ud800"}, now=0.0).msg
    data = registry.serialize(wide, msg)
    assert data[8:16] == bytes.fromhex("0100000000d80000")


def _with_plain(units: bytes, count: int) -> bytes:
    """``PINNED`` whose ``plain`` field claims ``count`` units and holds ``units``."""
    return PINNED[:8] + count.to_bytes(4, "little") + units + PINNED[28:]


def _count_at(offset: int, count: int) -> bytes:
    """``PINNED`` cut at ``offset``, where a count of ``count`` follows."""
    return PINNED[:offset] + count.to_bytes(4, "little")


SHORT = "cannot deserialize"  # rosbags found too few bytes


@pytest.mark.parametrize(
    ("data", "text"),
    [
        pytest.param(_with_plain(b"", 0xFFFFFFFF), SHORT, id="a count far past the end"),
        pytest.param(_with_plain(bytes.fromhex("6800000000000100"), 2), "above 0xFFFF", id="unit"),
        pytest.param(_with_plain(bytes.fromhex("00d80000"), 1), "not UTF-16", id="lone high"),
        pytest.param(_with_plain(bytes.fromhex("00de000068000000"), 2), "not UTF-16", id="low"),
        pytest.param(PINNED[:30], SHORT, id="cut inside a wstring"),
        pytest.param(_count_at(32, 2**31), SHORT, id="huge array element"),
        pytest.param(_count_at(48, 2**31), SHORT, id="huge sequence element"),
        pytest.param(_count_at(60, 2**28), SHORT, id="too many wstrings"),
    ],
)
def test_bytes_that_are_no_wstring_are_refused(
    registry: TypeRegistry, wide: MessageType, data: bytes, text: str
) -> None:
    with pytest.raises(CdrError, match=text):
        _decode(registry, wide, data)
