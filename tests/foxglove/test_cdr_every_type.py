"""rwt's CDR is rclpy's, for every message type whose hash is checked against rosidl's.

The ROS 2 Kilted wheels ship, for each of their message types, the JSON file whose
RIHS01 hashes tests/zenoh/test_rosidl_hashes.py compares with rwt's. For each such
type rclpy can import, a message with a value in every field (none at its default)
is serialized by rclpy; rwt reads those bytes as a Foxglove client's message data
is read (``decode_wire``), finds the same values, and serializes them back as
Foxglove message data is serialized (``encode_wire``): the same bytes, except for
alignment padding, which rclpy leaves uninitialised and rwt writes as zeros, and
the end, which rclpy may pad to a multiple of 4 bytes and rwt does not.
tests/foxglove/test_cdr_rclpy.py follows a few of them through a session's frames.
"""

from __future__ import annotations

import importlib
import sys
import warnings
from pathlib import Path
from typing import Any

import pytest

from rwt_foxglove.wire import decode_wire, encode_wire
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.errors import RwtError
from tests.ros2.support import skip_without_rclpy

SHARE = Path(sys.prefix) / "share"
CHECKED = sorted(
    f"{path.parent.parent.name}/msg/{path.stem}" for path in SHARE.glob("*/msg/*.json")
)

pytestmark = [
    skip_without_rclpy(),
    pytest.mark.skipif(not CHECKED, reason="the ROS 2 Kilted interface wheels are not installed"),
]

# a value of each basic type that is not its default (and not symmetric in its bytes)
BASIC: dict[str, object] = {
    "boolean": True,
    "octet": b"\x9c",
    "char": 67,
    "float": 1.5,
    "double": -2.75e100,
    "int8": -7,
    "uint8": 200,
    "int16": -300,
    "uint16": 60_000,
    "int32": -70_000,
    "uint32": 4_000_000_000,
    "int64": -(2**62) - 3,
    "uint64": 2**64 - 5,
}


def _message_class(name: str) -> Any:
    package, _, type_name = name.split("/")
    with warnings.catch_warnings():
        # rclpy's type support loads lark-parser 0.12, which imports the deprecated sre_parse
        warnings.simplefilter("ignore", DeprecationWarning)
        module = importlib.import_module(f"{package}.msg")
    return getattr(module, type_name)


def _value(slot: Any, index: int) -> object:
    """A value for a field of rosidl type ``slot`` (``rosidl_parser.definition``)."""
    kind = type(slot).__name__
    if kind == "BasicType":
        return BASIC[slot.typename]
    if kind in ("UnboundedString", "BoundedString"):
        return f"s{index}é"[: getattr(slot, "maximum_size", 8)]
    if kind in ("UnboundedWString", "BoundedWString"):
        # beyond Latin-1, and a character outside the BMP (a UTF-16 surrogate pair)
        return f"w{index}ö€😀"[: getattr(slot, "maximum_size", 8)]
    if kind == "NamespacedType":
        return _filled(_message_class("/".join([*slot.namespaces, slot.name])))
    if kind == "Array":
        return [_value(slot.value_type, index + n) for n in range(slot.size)]
    if kind in ("UnboundedSequence", "BoundedSequence"):
        count = min(2, getattr(slot, "maximum_size", 2))
        return [_value(slot.value_type, index + n) for n in range(count)]
    raise AssertionError(f"no value for {kind}")


def _filled(cls: Any) -> Any:
    """An instance of ``cls`` with a value in every field."""
    fields = list(cls.get_fields_and_field_types())
    pairs = zip(fields, cls.SLOT_TYPES, strict=True)
    return cls(**{f: _value(s, n) for n, (f, s) in enumerate(pairs)})


def _wstrings(message: Any) -> int:
    """How many wstrings ``message`` holds, at any depth."""

    def count(value: object) -> int:
        if isinstance(value, str):
            return 0
        if isinstance(value, list | tuple):
            return sum(count(item) for item in value)
        if hasattr(value, "SLOT_TYPES"):
            return _wstrings(value)
        return 0

    total = 0
    for field, slot in zip(message.get_fields_and_field_types(), message.SLOT_TYPES, strict=True):
        value = getattr(message, field)
        kinds = ("UnboundedWString", "BoundedWString")
        inner = getattr(slot, "value_type", slot)
        if type(inner).__name__ in kinds:
            total += len(value) if inner is not slot else 1
        else:
            total += count(value)
    return total


def _cases() -> list[str]:
    registry = TypeRegistry(Dialect.ROS2, [SHARE])
    names = []
    for name in CHECKED:
        try:
            registry.message(name)
            _message_class(name)
        except (RwtError, ImportError, AttributeError):
            continue  # a type rwt or rclpy cannot load here is not compared
        names.append(name)
    return names


CASES = _cases() if CHECKED else []


def test_the_compared_types_are_most_of_the_checked_ones() -> None:
    assert len(CASES) > 100 and len(CASES) >= 0.9 * len(CHECKED), (len(CASES), len(CHECKED))


@pytest.fixture(scope="module")
def registry() -> TypeRegistry:
    return TypeRegistry(Dialect.ROS2, [SHARE])


@pytest.mark.parametrize("type_name", CASES)
def test_rwt_reads_and_writes_rclpy_cdr(registry: TypeRegistry, type_name: str) -> None:
    from rclpy.serialization import deserialize_message, serialize_message  # noqa: PLC0415

    cls = _message_class(type_name)
    message = _filled(cls)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        theirs = bytes(serialize_message(message))
    mtype = registry.message(type_name)
    ours = encode_wire(registry, mtype, decode_wire(registry, mtype, theirs))
    # rclpy may pad the end up to a multiple of 4 bytes (uninitialised too), and its length
    # counts 4 bytes a wstring that it never writes (a terminator); rwt stops at the last field
    end = len(ours) + (-len(ours) % 4) + 4 * _wstrings(message)
    assert len(ours) <= len(theirs) <= end
    differ = [n for n, (a, b) in enumerate(zip(ours, theirs, strict=False)) if a not in (b, 0)]
    assert differ == [], (ours.hex(), theirs.hex())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        assert deserialize_message(ours, cls) == message


@pytest.mark.skipif("test_msgs/msg/WStrings" not in CASES, reason="test_msgs is not installed")
def test_wstrings_read_and_written_as_rclpy_does(registry: TypeRegistry) -> None:
    """Empty, non-ASCII and surrogate-pair text in every kind of wstring field, both ways."""
    from rclpy.serialization import serialize_message  # noqa: PLC0415

    texts = ["", "hé€😀", "😀😀"]
    message = _message_class("test_msgs/msg/WStrings")(
        wstring_value="hé€😀",
        wstring_value_default1="",
        array_of_wstrings=texts,
        bounded_sequence_of_wstrings=texts[1:],
        unbounded_sequence_of_wstrings=texts,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        theirs = bytes(serialize_message(message))
    mtype = registry.message("test_msgs/msg/WStrings")
    # the first wstring: 5 UTF-16 code units, each in 4 bytes, the emoji as two of them
    assert theirs[4:28].hex() == "0500000068000000e9000000ac2000003dd8000000de0000"
    decoded = decode_wire(registry, mtype, theirs)
    assert decoded["wstring_value"] == "hé€😀" and decoded["wstring_value_default1"] == ""
    assert decoded["array_of_wstrings"] == texts
    assert decoded["unbounded_sequence_of_wstrings"] == texts
    ours = encode_wire(registry, mtype, decoded)
    assert theirs[: len(ours)] == ours
