"""JSON -> internal conversion of primitives and arrays (D7, D9, D10)."""

from __future__ import annotations

import base64
import math
import tempfile
from collections import OrderedDict, UserList
from pathlib import Path

import msgspec
import pytest
from types_support import NOW, roundtrip, same

from rwt_graph.types import Dialect, TypeRegistry
from rwt_graph.types.primitives import json_kind, scalar_checker
from rwt_protocol.errors import FieldError

INTS = [
    ("Int8", "int8", -(2**7), 2**7 - 1),
    ("UInt8", "uint8", 0, 2**8 - 1),
    ("Int16", "int16", -(2**15), 2**15 - 1),
    ("UInt16", "uint16", 0, 2**16 - 1),
    ("Int32", "int32", -(2**31), 2**31 - 1),
    ("UInt32", "uint32", 0, 2**32 - 1),
    ("Int64", "int64", -(2**63), 2**63 - 1),
    ("UInt64", "uint64", 0, 2**64 - 1),
    ("Char", "char", 0, 255),
]


def convert(registry: TypeRegistry, name: str, value: object) -> dict[str, object]:
    return registry.message(name).from_json(value, path="$.msg", now=NOW).msg


def problem(registry: TypeRegistry, name: str, value: object) -> str:
    with pytest.raises(FieldError) as caught:
        convert(registry, name, value)
    return caught.value.message


@pytest.mark.parametrize(("cls", "base", "low", "high"), INTS)
def test_every_int_width_accepts_its_bounds_and_rejects_one_past(
    ros2: TypeRegistry, cls: str, base: str, low: int, high: int
) -> None:
    name = f"std_msgs/{cls}"
    for value in (low, high, (low + high) // 2):
        assert convert(ros2, name, {"data": value}) == {"data": value}
    text = problem(ros2, name, {"data": high + 1})
    shown = "uint8" if base == "char" and "uint8" in text else base
    assert text == f"expected {shown} in [{low}, {high}], got {high + 1} at $.msg.data"
    assert f"got {low - 1} at $.msg.data" in problem(ros2, name, {"data": low - 1})


@pytest.mark.parametrize("base", ["Int8", "UInt64", "Byte", "Char"])
def test_ints_reject_bools_floats_strings_and_null(ros2: TypeRegistry, base: str) -> None:
    name = f"std_msgs/{base}"
    for value, kind in ((True, "bool"), (3.0, "float"), ("3", "str"), (None, "null")):
        assert problem(ros2, name, {"data": value}).endswith(f", got {kind} at $.msg.data")


def test_byte_is_an_octet_in_ros2_and_int8_in_ros1(ros2: TypeRegistry, ros1: TypeRegistry) -> None:
    assert convert(ros2, "std_msgs/Byte", {"data": 255}) == {"data": 255}
    assert "expected byte in [0, 255], got -1" in problem(ros2, "std_msgs/Byte", {"data": -1})
    assert convert(ros1, "std_msgs/Byte", {"data": -128}) == {"data": -128}
    assert "expected byte in [-128, 127], got 128" in problem(ros1, "std_msgs/Byte", {"data": 128})
    assert convert(ros1, "std_msgs/Char", {"data": 255}) == {"data": 255}


def test_floats(ros2: TypeRegistry) -> None:
    assert convert(ros2, "std_msgs/Float64", {"data": 3}) == {"data": 3.0}
    assert type(convert(ros2, "std_msgs/Float64", {"data": 3})["data"]) is float
    assert convert(ros2, "std_msgs/Float32", {"data": 3.4028234663852886e38})["data"] > 0
    for value in (math.inf, -math.inf):
        assert convert(ros2, "std_msgs/Float32", {"data": value}) == {"data": value}
    assert math.isnan(convert(ros2, "std_msgs/Float64", {"data": None})["data"])  # type: ignore[arg-type]
    assert math.isnan(convert(ros2, "std_msgs/Float32", {"data": math.nan})["data"])  # type: ignore[arg-type]
    assert problem(ros2, "std_msgs/Float32", {"data": 3.5e38}) == (
        "expected float32 in [-3.4028234663852886e+38, 3.4028234663852886e+38], "
        "got 3.5e+38 at $.msg.data"
    )
    assert f"got {-(10**39)} at" in problem(ros2, "std_msgs/Float32", {"data": -(10**39)})
    assert "expected float64 in" in problem(ros2, "std_msgs/Float64", {"data": 10**400})
    assert problem(ros2, "std_msgs/Float64", {"data": True}) == (
        "expected float64, got bool at $.msg.data"
    )
    assert problem(ros2, "std_msgs/Float64", {"data": "1"}).startswith("expected float64, got str")


def test_non_finite_floats_go_out_as_null_and_come_back(ros2: TypeRegistry) -> None:
    mtype = ros2.message("std_msgs/Float64MultiArray")
    msg = mtype.from_json({"data": [math.inf, -math.inf, math.nan, 1.5]}, now=NOW).msg
    encoded = msgspec.json.encode(msg)
    assert b'"data":[null,null,null,1.5]' in encoded
    back = mtype.from_json(msgspec.json.decode(encoded), now=NOW).msg
    assert all(math.isnan(x) for x in back["data"][:3])  # type: ignore[index]


def test_bools_and_strings(ros2: TypeRegistry) -> None:
    assert convert(ros2, "std_msgs/Bool", {"data": False}) == {"data": False}
    assert problem(ros2, "std_msgs/Bool", {"data": 1}) == "expected bool, got int at $.msg.data"
    assert problem(ros2, "std_msgs/Bool", {"data": 0}) == "expected bool, got int at $.msg.data"
    assert convert(ros2, "std_msgs/String", {"data": "int32"}) == {"data": "int32"}
    assert problem(ros2, "std_msgs/String", {"data": 3}) == "expected string, got int at $.msg.data"
    assert problem(ros2, "std_msgs/String", {"data": ["a"]}).startswith(
        "expected string, got array"
    )
    assert problem(ros2, "std_msgs/String", {"data": {}}).startswith("expected string, got object")


def test_message_shape_errors(ros2: TypeRegistry) -> None:
    assert problem(ros2, "std_msgs/String", "hi") == (
        "expected object (type std_msgs/msg/String), got str at $.msg"
    )
    assert problem(ros2, "std_msgs/String", {"data": "x", "foo": 1}) == (
        "unknown field 'foo' at $.msg"
    )
    assert problem(ros2, "geometry_msgs/Pose", {"position": {"x": 1, "w": 2}}) == (
        "unknown field 'w' at $.msg.position"
    )
    assert problem(ros2, "geometry_msgs/Pose", {"position": {"x": "1"}}) == (
        "expected float64, got str at $.msg.position.x"
    )
    assert problem(ros2, "geometry_msgs/Pose", {"position": []}) == (
        "expected object (type geometry_msgs/msg/Point), got array at $.msg.position"
    )
    assert problem(
        ros2,
        "geometry_msgs/PoseArray",
        {"poses": [{}, {"position": {"y": None}}, {"orientation": 1}]},
    ) == (
        "expected object (type geometry_msgs/msg/Quaternion), got int at $.msg.poses[2].orientation"
    )
    assert problem(ros2, "geometry_msgs/PoseArray", {"poses": {}}) == (
        "expected geometry_msgs/msg/Pose[], got object at $.msg.poses"
    )


def test_missing_fields_are_reported_once_per_omitted_subtree(ros2: TypeRegistry) -> None:
    result = ros2.message("geometry_msgs/PoseStamped").from_json(
        {"pose": {"position": {"x": 1.0}}}, path="$.msg", now=NOW
    )
    assert result.missing == (
        "$.msg.header",
        "$.msg.pose.position.y",
        "$.msg.pose.position.z",
        "$.msg.pose.orientation",
    )
    assert result.msg["pose"] == {
        "position": {"x": 1.0, "y": 0.0, "z": 0.0},
        "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
    }
    assert list(result.msg) == ["header", "pose"]


def test_quaternion_w_defaults_to_one_in_ros2_only(ros2: TypeRegistry, ros1: TypeRegistry) -> None:
    assert ros2.message("geometry_msgs/Quaternion").default()["w"] == 1.0
    assert convert(ros2, "geometry_msgs/Quaternion", {"x": 0.5})["w"] == 1.0
    assert convert(ros1, "geometry_msgs/Quaternion", {})["w"] == 0.0


@pytest.mark.parametrize("dialect", list(Dialect))
def test_uint8_arrays_accept_base64_or_ints_and_become_bytes(dialect: Dialect) -> None:
    registry = TypeRegistry(dialect)
    data = bytes(range(256))
    mtype = registry.message("std_msgs/UInt8MultiArray")
    as_list = mtype.from_json({"data": list(range(256))}, now=NOW).msg
    as_b64 = mtype.from_json({"data": base64.b64encode(data).decode()}, now=NOW).msg
    assert as_list["data"] == as_b64["data"] == data
    assert msgspec.json.encode(as_list).endswith(b'"data":"' + base64.b64encode(data) + b'"}')
    assert mtype.from_json({"data": ""}, now=NOW).msg["data"] == b""
    with pytest.raises(FieldError, match=r"expected uint8 in \[0, 255\], got 256 at \$.data\[1\]"):
        mtype.from_json({"data": [0, 256]}, now=NOW)
    with pytest.raises(FieldError, match=r"expected uint8, got bool at \$.data\[2\]"):
        mtype.from_json({"data": [0, 1, True]}, now=NOW)
    with pytest.raises(FieldError, match=r"invalid base64 at \$.data"):
        mtype.from_json({"data": "not base64!"}, now=NOW)
    with pytest.raises(FieldError, match=r"base64 string or array\), got int at \$.data"):
        mtype.from_json({"data": 7}, now=NOW)


def test_byte_arrays_are_lists_of_octets_in_ros2(ros2: TypeRegistry) -> None:
    mtype = ros2.message("std_msgs/ByteMultiArray")
    msg = mtype.from_json({"data": [0, 128, 255]}, now=NOW).msg
    assert msg["data"] == [0, 128, 255]
    assert b'"data":[0,128,255]' in msgspec.json.encode(msg)
    with pytest.raises(FieldError, match=r"expected byte in \[0, 255\], got -1 at \$.data\[0\]"):
        mtype.from_json({"data": [-1]}, now=NOW)


LIMITS = "rwt_test_msgs/Limits"


def test_fixed_and_bounded_uint8_and_char_arrays(ros2: TypeRegistry) -> None:
    uuid = bytes(range(16))
    msg = convert(ros2, LIMITS, {"uuid": list(range(16)), "small_bytes": [1, 2], "chars": "YWI="})
    assert msg["uuid"] == uuid and msg["small_bytes"] == b"\x01\x02" and msg["chars"] == b"ab"
    assert convert(ros2, LIMITS, {"uuid": base64.b64encode(uuid).decode()})["uuid"] == uuid
    assert ros2.message(LIMITS).default()["uuid"] == bytes(16)
    assert problem(ros2, LIMITS, {"uuid": [1, 2, 3]}) == "expected 16 elements, got 3 at $.msg.uuid"
    assert problem(ros2, LIMITS, {"uuid": "AAAA"}) == "expected 16 elements, got 3 at $.msg.uuid"
    assert problem(ros2, LIMITS, {"small_bytes": [0] * 5}) == (
        "expected at most 4 elements, got 5 at $.msg.small_bytes"
    )


def test_fixed_and_bounded_arrays_and_strings(ros2: TypeRegistry) -> None:
    assert convert(ros2, LIMITS, {"covariance": list(range(9))})["covariance"] == [
        float(i) for i in range(9)
    ]
    assert problem(ros2, LIMITS, {"covariance": [0.0] * 3}) == (
        "expected 9 elements, got 3 at $.msg.covariance"
    )
    assert convert(ros2, LIMITS, {"bounded_floats": list(range(16))})["bounded_floats"] == [
        float(i) for i in range(16)
    ]
    assert problem(ros2, LIMITS, {"bounded_floats": [0.0] * 17}) == (
        "expected at most 16 elements, got 17 at $.msg.bounded_floats"
    )
    assert problem(ros2, LIMITS, {"bounded_floats": [0.0, 1e39]}).endswith(
        "got 1e+39 at $.msg.bounded_floats[1]"
    )
    assert problem(ros2, LIMITS, {"few_ints": [1, "2"]}) == (
        "expected int32, got str at $.msg.few_ints[1]"
    )
    assert problem(ros2, LIMITS, {"few_ints": [1, 2**31]}).endswith(
        "got 2147483648 at $.msg.few_ints[1]"
    )
    assert (
        problem(ros2, LIMITS, {"few_ints": "1"}) == "expected int32[<=3], got str at $.msg.few_ints"
    )
    assert convert(ros2, LIMITS, {"short_name": "abcde"})["short_name"] == "abcde"
    assert problem(ros2, LIMITS, {"short_name": "abcdef"}) == (
        "expected string of at most 5 characters, got 6 at $.msg.short_name"
    )
    assert problem(ros2, LIMITS, {"tags": ["abc", "abcd"]}) == (
        "expected string of at most 3 characters, got 4 at $.msg.tags[1]"
    )
    assert problem(ros2, LIMITS, {"flags": [True, 1]}) == "expected bool, got int at $.msg.flags[1]"
    assert problem(ros2, LIMITS, {"octets": [1.0]}) == "expected byte, got float at $.msg.octets[0]"


def test_limits_round_trip(ros2: TypeRegistry) -> None:
    mtype = ros2.message(LIMITS)
    msg = mtype.from_json(
        {
            "uuid": list(range(16)),
            "small_bytes": [9],
            "chars": [65],
            "octets": [255, 0],
            "covariance": [math.nan, *range(8)],
            "bounded_floats": [1.5, -2.5],
            "few_ints": [-1, 0, 1],
            "short_name": "ok",
            "tags": ["a", "bc"],
            "flags": [True, False],
        },
        now=NOW,
    ).msg
    assert same(roundtrip(mtype, msg), msg)


def test_arrays_of_messages_check_their_length(ros2: TypeRegistry) -> None:
    inner = "rwt_test_msgs/Inner"
    assert problem(ros2, inner, {"pair": [{}]}) == "expected 2 elements, got 1 at $.msg.pair"
    assert problem(ros2, inner, {"pair": [{}, {"stamp": 1}]}) == (
        "expected object (type builtin_interfaces/msg/Time), got int at $.msg.pair[1].stamp"
    )
    bounded = TypeRegistry(interface_dirs=[_bounded_dir()]).message("pkg/Bounded")
    assert (
        bounded.from_json({"points": [{}, {}]}, now=NOW).msg["points"]
        == [{"x": 0.0, "y": 0.0, "z": 0.0}] * 2
    )
    with pytest.raises(FieldError, match=r"expected at most 2 elements, got 3 at \$.points"):
        bounded.from_json({"points": [{}, {}, {}]}, now=NOW)


def _bounded_dir() -> Path:
    root = Path(tempfile.mkdtemp())
    (root / "pkg" / "msg").mkdir(parents=True)
    (root / "pkg" / "msg" / "Bounded.msg").write_text(
        "geometry_msgs/Point[<=2] points\nstring<=2 code\n"
    )
    return root


def test_bounded_string_rejects_non_strings() -> None:
    bounded = TypeRegistry(interface_dirs=[_bounded_dir()]).message("pkg/Bounded")
    with pytest.raises(FieldError, match=r"expected string<=2, got null at \$.code"):
        bounded.from_json({"code": None}, now=NOW)


def test_json_kind_names_and_checker_misuse() -> None:
    assert json_kind(OrderedDict()) == "object"
    assert json_kind(type("L", (list,), {})()) == "array"
    assert json_kind(b"x") == "bytes"
    assert json_kind(UserList()) == "UserList"
    with pytest.raises(ValueError, match="not a scalar primitive"):
        scalar_checker("time", Dialect.ROS2)
