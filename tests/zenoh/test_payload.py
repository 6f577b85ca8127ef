"""Sample payloads are rosbags' own CDR, both ways (rwt_zenoh.payload)."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from rwt_graph.types import Dialect, TypeRegistry
from rwt_zenoh.payload import decode_sample, encode_sample, service_hash, type_hash
from rwt_zenoh.wire import WireError

JAZZY = get_typestore(Stores.ROS2_JAZZY)
REGISTRY = TypeRegistry(Dialect.ROS2)


def test_a_string_is_rosbags_cdr_and_comes_back() -> None:
    String = JAZZY.types["std_msgs/msg/String"]
    expected = bytes(JAZZY.serialize_cdr(String(data="héllo"), "std_msgs/msg/String"))
    data = encode_sample(REGISTRY, "std_msgs/msg/String", {"data": "héllo"})
    assert data == expected
    assert decode_sample(REGISTRY, "std_msgs/msg/String", data) == {"data": "héllo"}


def test_nested_arrays_and_time_come_back_field_by_field() -> None:
    msg = {
        "header": {"stamp": {"sec": 12, "nanosec": 345}, "frame_id": "laser"},
        "angle_min": -1.5,
        "angle_max": 1.5,
        "angle_increment": 0.5,
        "time_increment": 0.0,
        "scan_time": 0.1,
        "range_min": 0.1,
        "range_max": 10.0,
        "ranges": [1.0, 2.0, 3.0],
        "intensities": [],
    }
    data = encode_sample(REGISTRY, "sensor_msgs/msg/LaserScan", msg)
    obj = JAZZY.deserialize_cdr(data, "sensor_msgs/msg/LaserScan")
    assert obj.header.frame_id == "laser" and obj.header.stamp.nanosec == 345
    np.testing.assert_allclose(obj.ranges, [1.0, 2.0, 3.0])
    back = decode_sample(REGISTRY, "sensor_msgs/msg/LaserScan", data)
    assert back["header"] == msg["header"]
    assert list(back["ranges"]) == [1.0, 2.0, 3.0]  # type: ignore[call-overload]


def test_type_hashes_are_rihs01() -> None:
    assert type_hash(REGISTRY, "std_msgs/msg/String") == JAZZY.hash_rihs01("std_msgs/msg/String")
    assert type_hash(REGISTRY, "std_msgs/String").startswith("RIHS01_")


def test_garbage_bytes_are_a_wire_error() -> None:
    with pytest.raises(WireError):
        decode_sample(REGISTRY, "sensor_msgs/msg/LaserScan", b"\x00\x01\x00\x00\xff")


def test_ros1_registries_are_refused() -> None:
    with pytest.raises(WireError):
        encode_sample(TypeRegistry(Dialect.ROS1), "std_msgs/String", {"data": "x"})


# rosidl's own hashes of std_srvs/srv/SetBool, from the C code rosidl_generator_c
# generated for it (set_bool__description.c: std_srvs__srv__SetBool__get_type_hash
# and std_srvs__srv__SetBool_Request__get_type_hash), as published in the micro-ROS
# headers of github.com/hpmicro/hpm_sdk
# (middleware/microros/kilted/include/std_srvs/std_srvs/srv/detail/).
SET_BOOL_HASH = "RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a"
SET_BOOL_REQUEST_HASH = "RIHS01_c62fbb99d94e1b25e8ef9e109f9581956bb1b3361a45a4e5810c36a90d29932e"


def test_a_service_hash_is_rosidls_hash_of_the_service() -> None:
    srvtype = REGISTRY.service("std_srvs/srv/SetBool")
    assert service_hash(REGISTRY, srvtype) == SET_BOOL_HASH
    # not the request's hash, which keys carried before
    assert type_hash(REGISTRY, "std_srvs/srv/SetBool_Request") == SET_BOOL_REQUEST_HASH


def test_a_service_hash_depends_on_both_parts() -> None:
    hashes = {
        service_hash(REGISTRY, REGISTRY.service(name))
        for name in ("std_srvs/srv/SetBool", "std_srvs/srv/Trigger", "std_srvs/srv/Empty")
    }
    assert len(hashes) == 3
    assert all(text.startswith("RIHS01_") and len(text) == 71 for text in hashes)
