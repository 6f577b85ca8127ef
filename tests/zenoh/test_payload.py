"""Sample payloads are rosbags' own CDR, both ways (rwt_zenoh.payload)."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from rwt_graph.types import Dialect, TypeRegistry
from rwt_zenoh.actions import ActionWire
from rwt_zenoh.payload import (
    decode_sample,
    encode_sample,
    message_hash,
    named_service_hash,
    service_hash,
    type_hash,
)
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


# rosidl's hash of std_msgs/msg/Char ("char data"), from the C code rosidl_generator_c
# generated for it (char__description.c: std_msgs__msg__Char__get_type_hash), whose
# type description gives the field FIELD_TYPE_UINT8: rosidl reads a .msg char as uint8.
CHAR_HASH = "RIHS01_3ad2d04dd29ba19d04b16659afa3ccaedd691914b02a64e82e252f2fa6a586a9"


def test_a_char_field_hashes_as_rosidls_uint8() -> None:
    assert type_hash(REGISTRY, "std_msgs/msg/Char") == CHAR_HASH
    assert JAZZY.hash_rihs01("std_msgs/msg/Char") != CHAR_HASH  # rosbags alone keeps char


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


# The key of the add_two_ints service (example_interfaces/srv/AddTwoInts) in
# rmw_zenoh's docs/design.md, "Topic and Service name mapping to Zenoh key expressions".
ADD_TWO_INTS_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"


def test_a_service_hash_is_the_one_rmw_zenoh_shows() -> None:
    srvtype = REGISTRY.service("example_interfaces/srv/AddTwoInts")
    assert service_hash(REGISTRY, srvtype) == ADD_TWO_INTS_HASH


# rosidl's hashes of example_interfaces/action/Fibonacci's parts, from the C header
# rosidl_generator_c generated for it (fibonacci__struct.h, Jazzy's "Type Hash for
# interface" form: example_interfaces__action__Fibonacci_SendGoal__TYPE_HASH and its
# GetResult and FeedbackMessage twins). rmw_zenoh keys an action's two services by
# the service's hash (rmw_service_data.cpp: type_support->get_type_hash_func).
FIBONACCI = {
    "SendGoal": "RIHS01_d1a57fb2a4afe8c21e34fb10db206f16ce6729b28531141472df92277c55b557",
    "GetResult": "RIHS01_1b0de0d5d29dc955d92f546706568428632771db13ec84c15ec1c1a59f424a57",
    "FeedbackMessage": "RIHS01_c1de71afd52e49a89c53d8262366884185bc0a02f78ce051c4e46b0a7fe59bb2",
}


def test_an_actions_parts_hash_as_rosidl_hashes_them() -> None:
    ActionWire(REGISTRY, REGISTRY.action("example_interfaces/action/Fibonacci"))  # its parts
    base = "example_interfaces/action/Fibonacci"
    assert named_service_hash(REGISTRY, f"{base}_SendGoal") == FIBONACCI["SendGoal"]
    assert named_service_hash(REGISTRY, f"{base}_GetResult") == FIBONACCI["GetResult"]
    assert message_hash(REGISTRY, f"{base}_FeedbackMessage") == FIBONACCI["FeedbackMessage"]


def test_a_service_hash_depends_on_both_parts() -> None:
    hashes = {
        service_hash(REGISTRY, REGISTRY.service(name))
        for name in ("std_srvs/srv/SetBool", "std_srvs/srv/Trigger", "std_srvs/srv/Empty")
    }
    assert len(hashes) == 3
    assert all(text.startswith("RIHS01_") and len(text) == 71 for text in hashes)


def test_a_large_message_comes_back_whole() -> None:
    # 1 MB: rosbags reads it through a view (rwt_graph.types.wire.wire_input)
    pixels = bytes(range(256)) * 4096
    msg = {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "cam"},
        "height": 1024,
        "width": 1024,
        "encoding": "mono8",
        "is_bigendian": 0,
        "step": 1024,
        "data": pixels,
    }
    data = encode_sample(REGISTRY, "sensor_msgs/msg/Image", msg)
    back = decode_sample(REGISTRY, "sensor_msgs/msg/Image", data)
    assert back["data"] == pixels
    assert isinstance(back["data"], bytes)
    assert back["header"] == msg["header"]
    assert (back["height"], back["width"], back["encoding"]) == (1024, 1024, "mono8")


@pytest.mark.parametrize(
    "body",
    [b"\xff" * 100_000, (10**9).to_bytes(4, "little") * 30_000, b"\xed\xa0\x80" * 40_000],
    ids=["ones", "huge-lengths", "surrogate-bytes"],
)
def test_large_garbage_read_through_a_view_is_a_wire_error(body: bytes) -> None:
    with pytest.raises(WireError):
        decode_sample(REGISTRY, "sensor_msgs/msg/Image", b"\x00\x01\x00\x00" + body)
