"""Real message types: round trips, header fill and times (D6, D8; REF §4.3, §8.4 L50-L54)."""

from __future__ import annotations

import base64
import math

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st
from types_support import NOW, roundtrip, same

from rwt_graph.types import TypeRegistry
from rwt_protocol.errors import FieldError

NOW_ROS2 = {"sec": 1_700_000_000, "nanosec": 250_000_000}
NOW_ROS1 = {"secs": 1_700_000_000, "nsecs": 250_000_000}
STAMP = {"sec": 12347, "nanosec": 322304}


def test_pose_and_twist_round_trip(ros2: TypeRegistry) -> None:
    pose = ros2.message("geometry_msgs/Pose")
    msg = pose.from_json(
        {"position": {"x": 1, "y": -2.5, "z": 1e-9}, "orientation": {"x": 0, "y": 0, "z": 0.7}},
        now=NOW,
    ).msg
    assert msg == {
        "position": {"x": 1.0, "y": -2.5, "z": 1e-9},
        "orientation": {"x": 0.0, "y": 0.0, "z": 0.7, "w": 1.0},
    }
    assert same(roundtrip(pose, msg), msg)
    twist = ros2.message("geometry_msgs/msg/Twist")
    msg = twist.from_json({"linear": {"x": 0.5}, "angular": {"z": -1}}, now=NOW).msg
    assert same(roundtrip(twist, msg), msg)


finite = st.floats(allow_nan=False, allow_infinity=False)
vector = st.fixed_dictionaries({"x": finite, "y": finite, "z": finite})


@given(st.fixed_dictionaries({"linear": vector, "angular": vector}))
def test_any_twist_round_trips(value: dict[str, object]) -> None:
    twist = TypeRegistry().message("geometry_msgs/Twist")
    msg = twist.from_json(value, now=NOW).msg
    assert msg == value
    assert roundtrip(twist, msg) == value


@given(
    st.lists(st.integers(-(2**63), 2**63 - 1), max_size=20),
    st.lists(st.floats(width=32, allow_infinity=False), max_size=20),
)
def test_any_int64_and_float32_arrays_round_trip(ints: list[int], floats: list[float]) -> None:
    # Infinities are left out: they go out as null, which comes back as NaN (D10).
    registry = TypeRegistry()
    int_type = registry.message("std_msgs/Int64MultiArray")
    msg = int_type.from_json({"data": ints}, now=NOW).msg
    assert roundtrip(int_type, msg)["data"] == ints
    float_type = registry.message("std_msgs/Float32MultiArray")
    msg = float_type.from_json({"data": floats}, now=NOW).msg
    assert same(roundtrip(float_type, msg), msg)


def image_json(data: object) -> dict[str, object]:
    return {
        "header": {"stamp": STAMP, "frame_id": "camera"},
        "height": 480,
        "width": 640,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": 640 * 3,
        "data": data,
    }


def test_image_640x480_from_base64_and_from_int_list(ros2: TypeRegistry) -> None:
    pixels = bytes(i % 251 for i in range(640 * 480 * 3))
    image = ros2.message("sensor_msgs/Image")
    from_b64 = image.from_json(image_json(base64.b64encode(pixels).decode()), now=NOW).msg
    from_list = image.from_json(image_json(list(pixels)), now=NOW).msg
    assert from_b64 == from_list
    assert from_b64["data"] == pixels
    assert same(roundtrip(image, from_b64), from_b64)
    with pytest.raises(FieldError, match=r"got 300 at \$.msg.data\[5\]"):
        image.from_json(image_json([0, 0, 0, 0, 0, 300]), path="$.msg", now=NOW)


def test_pointcloud2_round_trip(ros2: TypeRegistry) -> None:
    cloud = ros2.message("sensor_msgs/PointCloud2")
    fields = [
        {"name": name, "offset": 4 * i, "datatype": 7, "count": 1} for i, name in enumerate("xyz")
    ]
    msg = cloud.from_json(
        {
            "header": {"stamp": STAMP, "frame_id": "lidar"},
            "height": 1,
            "width": 2,
            "fields": fields,
            "is_bigendian": False,
            "point_step": 12,
            "row_step": 24,
            "data": base64.b64encode(bytes(24)).decode(),
            "is_dense": True,
        },
        now=NOW,
    ).msg
    assert msg["data"] == bytes(24)
    assert msg["fields"][2] == {"name": "z", "offset": 8, "datatype": 7, "count": 1}  # type: ignore[index]
    assert same(roundtrip(cloud, msg), msg)


def test_occupancy_grid_data_is_an_int8_list(ros2: TypeRegistry) -> None:
    grid = ros2.message("nav_msgs/OccupancyGrid")
    msg = grid.from_json(
        {
            "header": {"stamp": STAMP, "frame_id": "map"},
            "info": {
                "map_load_time": STAMP,
                "resolution": 0.05,
                "width": 2,
                "height": 2,
                "origin": {"position": {"x": -1.0}, "orientation": {"w": 1.0}},
            },
            "data": [-1, 0, 100, 50],
        },
        now=NOW,
    )
    assert msg.msg["data"] == [-1, 0, 100, 50]
    assert msg.missing == (
        "$.info.origin.position.y",
        "$.info.origin.position.z",
        "$.info.origin.orientation.x",
        "$.info.origin.orientation.y",
        "$.info.origin.orientation.z",
    )
    assert same(roundtrip(grid, msg.msg), msg.msg)
    with pytest.raises(
        FieldError, match=r"expected int8 in \[-128, 127\], got 128 at \$.data\[0\]"
    ):
        grid.from_json({"data": [128]}, now=NOW)


def test_joint_state_and_tf_message(ros2: TypeRegistry) -> None:
    joints = ros2.message("sensor_msgs/JointState")
    msg = joints.from_json(
        {"name": ["a", "b"], "position": [1, 2.5], "velocity": [], "effort": [None]}, now=NOW
    ).msg
    assert msg["position"] == [1.0, 2.5]
    assert math.isnan(msg["effort"][0])  # type: ignore[index]
    assert same(roundtrip(joints, msg), msg)
    tf = ros2.message("tf2_msgs/TFMessage")
    transform = {
        "header": {"stamp": STAMP, "frame_id": "world"},
        "child_frame_id": "base",
        "transform": {"translation": {"x": 1.0}, "rotation": {"z": 1.0, "w": 0.0}},
    }
    msg = tf.from_json({"transforms": [transform, transform]}, now=NOW).msg
    assert msg["transforms"][1]["transform"]["rotation"] == {  # type: ignore[index]
        "x": 0.0,
        "y": 0.0,
        "z": 1.0,
        "w": 0.0,
    }
    assert same(roundtrip(tf, msg), msg)


def test_navsatfix_nan_covariance_goes_out_as_null_and_back(ros2: TypeRegistry) -> None:
    fix = ros2.message("sensor_msgs/NavSatFix")
    msg = fix.from_json(
        {"latitude": 48.1, "position_covariance": [math.nan] + [0.0] * 8}, now=NOW
    ).msg
    encoded = msgspec.json.encode(msg)
    assert b'"position_covariance":[null,0.0,' in encoded
    back = fix.from_json(msgspec.json.decode(encoded), now=NOW).msg
    assert math.isnan(back["position_covariance"][0])  # type: ignore[index]
    assert same(back, msg)


def test_header_omitted_gets_now_and_empty_frame(ros2: TypeRegistry) -> None:
    stamped = ros2.message("geometry_msgs/PointStamped")
    assert stamped.has_header
    assert not ros2.message("geometry_msgs/Point").has_header
    result = stamped.from_json({"point": {"x": 1.0, "y": 2.0, "z": 3.0}}, now=NOW)
    assert result.msg["header"] == {"stamp": NOW_ROS2, "frame_id": ""}
    assert result.missing == ("$.header",)


def test_header_without_stamp_gets_now_and_given_stamp_is_kept(ros2: TypeRegistry) -> None:
    stamped = ros2.message("geometry_msgs/PointStamped")
    result = stamped.from_json({"header": {"frame_id": "map"}, "point": {}}, now=NOW)
    assert result.msg["header"] == {"stamp": NOW_ROS2, "frame_id": "map"}
    assert "$.header.stamp" in result.missing
    kept = stamped.from_json({"header": {"stamp": STAMP, "frame_id": "x"}}, now=NOW).msg
    assert kept["header"] == {"stamp": STAMP, "frame_id": "x"}
    header = ros2.message("std_msgs/Header")
    alone = {"stamp": STAMP, "frame_id": "2394dnfnlcx;v[p234j]"}
    assert header.from_json(alone, now=NOW).msg == alone
    assert header.has_header


def test_headers_inside_arrays_and_nested_messages(ros2: TypeRegistry) -> None:
    stamped = ros2.message("rwt_test_msgs/Stamped")
    assert stamped.has_header
    msg = stamped.from_json(
        {"history": [{}, {"stamp": STAMP}, {"frame_id": "f"}], "inner": {"pair": [{}, {}]}},
        now=NOW,
    ).msg
    assert msg["header"]["stamp"] == NOW_ROS2  # type: ignore[index]
    assert [h["stamp"] for h in msg["history"]] == [NOW_ROS2, STAMP, NOW_ROS2]  # type: ignore[attr-defined,index]
    assert msg["inner"]["pair"] == [{"stamp": NOW_ROS2, "frame_id": ""}] * 2  # type: ignore[index]
    assert msg["inner"]["span"] == {"sec": 0, "nanosec": 0}  # type: ignore[index]
    omitted = stamped.from_json({}, now=NOW).msg
    assert omitted["inner"]["pair"] == [{"stamp": NOW_ROS2, "frame_id": ""}] * 2  # type: ignore[index]
    assert stamped.default()["inner"]["pair"][0]["stamp"] == {"sec": 0, "nanosec": 0}  # type: ignore[index]


def test_times_accept_both_spellings_and_now(ros2: TypeRegistry) -> None:
    header = ros2.message("std_msgs/Header")
    for stamp in ({"sec": 3, "nanosec": 5}, {"secs": 3, "nsecs": 5}, {"sec": 3, "nsecs": 5}):
        assert header.from_json({"stamp": stamp}, now=NOW).msg["stamp"] == {"sec": 3, "nanosec": 5}
    assert header.from_json({"stamp": "now"}, now=NOW).msg["stamp"] == NOW_ROS2
    partial = header.from_json({"stamp": {"sec": 3}, "frame_id": ""}, path="$.h", now=NOW)
    assert partial.msg["stamp"] == {"sec": 3, "nanosec": 0}
    assert partial.missing == ("$.h.stamp.nanosec",)
    time_type = ros2.message("builtin_interfaces/Time")
    assert time_type.from_json({"secs": 1, "nsecs": 2}, now=NOW).msg == {"sec": 1, "nanosec": 2}


@pytest.mark.parametrize(
    ("value", "text"),
    [
        ({"sec": 1, "secs": 1}, "expected one of 'sec' and 'secs', got both at $.stamp"),
        ({"sec": 1.5}, "expected int32, got float at $.stamp.sec"),
        ({"nanosec": -1}, "expected uint32 in [0, 4294967295], got -1 at $.stamp.nanosec"),
        ({"sec": 1, "nanoseconds": 2}, "unknown field 'nanoseconds' at $.stamp"),
        ("later", "expected object (type builtin_interfaces/msg/Time), got str at $.stamp"),
    ],
)
def test_bad_times(ros2: TypeRegistry, value: object, text: str) -> None:
    with pytest.raises(FieldError) as caught:
        ros2.message("std_msgs/Header").from_json({"stamp": value}, now=NOW)
    assert caught.value.message == text


def test_now_is_only_for_times_not_durations(ros2: TypeRegistry) -> None:
    with pytest.raises(FieldError, match=r"type builtin_interfaces/msg/Duration\), got str"):
        ros2.message("rwt_test_msgs/Inner").from_json({"span": "now"}, now=NOW)
    durations = ros2.message("rwt_test_msgs/Inner")
    assert durations.from_json({"span": {"secs": -2, "nsecs": 7}}, now=NOW).msg["span"] == {
        "sec": -2,
        "nanosec": 7,
    }


def test_ros1_dialect_times_and_header_seq(ros1: TypeRegistry) -> None:
    header = ros1.message("std_msgs/Header")
    assert [spec.name for spec in header.fields] == ["seq", "stamp", "frame_id"]
    msg = header.from_json({"seq": 4, "stamp": {"sec": 3, "nanosec": 5}}, now=NOW).msg
    assert msg == {"seq": 4, "stamp": {"secs": 3, "nsecs": 5}, "frame_id": ""}
    assert header.from_json({"stamp": "now"}, now=NOW).msg["stamp"] == NOW_ROS1
    stamped = ros1.message("geometry_msgs/PointStamped")
    assert stamped.from_json({}, now=NOW).msg["header"] == {
        "seq": 0,
        "stamp": NOW_ROS1,
        "frame_id": "",
    }
    with pytest.raises(
        FieldError, match=r"expected uint32 in \[0, 4294967295\], got -1 at \$.stamp.secs"
    ):
        header.from_json({"stamp": {"secs": -1}}, now=NOW)
    image = ros1.message("sensor_msgs/Image")
    assert image.from_json({"data": [1, 2]}, now=NOW).msg["data"] == b"\x01\x02"
    assert ros1.message("std_msgs/Duration").from_json({"data": {"secs": -1}}, now=NOW).msg == {
        "data": {"secs": -1, "nsecs": 0}
    }
    assert same(roundtrip(stamped, stamped.default(now=NOW)), stamped.default(now=NOW))
