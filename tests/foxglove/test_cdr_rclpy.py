"""The message data a Foxglove client gets is rclpy's own CDR, byte for byte.

foxglove_bridge sends what rclcpp serialized; rwt serializes graph messages with
rosbags. For a representative set of types, the payload of a message data frame
must equal ``rclpy.serialization.serialize_message`` of the same message, except
for alignment padding, which rclpy leaves uninitialised.
"""

from __future__ import annotations

import json
import struct
import sys
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

from rwt_foxglove import FoxgloveSession
from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from tests.ros2.support import skip_without_rclpy

pytestmark = skip_without_rclpy()

INT64_MIN, INT64_MAX, UINT64_MAX = -(2**63), 2**63 - 1, 2**64 - 1


def _string() -> object:
    from std_msgs.msg import String  # noqa: PLC0415

    return String(data="héllo foxglove")


def _image() -> object:
    from builtin_interfaces.msg import Time  # noqa: PLC0415
    from sensor_msgs.msg import Image  # noqa: PLC0415
    from std_msgs.msg import Header  # noqa: PLC0415

    return Image(
        header=Header(stamp=Time(sec=1_700_000_000, nanosec=123_456_789), frame_id="camera"),
        height=2,
        width=3,
        encoding="rgb8",
        is_bigendian=0,
        step=9,
        data=bytes(range(18)),
    )


def _twist() -> object:
    from geometry_msgs.msg import Twist, Vector3  # noqa: PLC0415

    return Twist(linear=Vector3(x=1.5, y=-2.25, z=0.0), angular=Vector3(x=0.0, y=0.0, z=3.0))


def _arrays() -> object:
    from test_msgs.msg import UnboundedSequences  # noqa: PLC0415

    return UnboundedSequences(
        int64_values=[INT64_MIN, 0, INT64_MAX],
        uint64_values=[0, UINT64_MAX],
        string_values=["a", "", "ccc"],
        float64_values=[0.5, -1e300],
        bool_values=[True, False, True],
        byte_values=[b"\x00", b"\xff"],
        alignment_check=7,
    )


def _basic() -> object:
    from test_msgs.msg import BasicTypes  # noqa: PLC0415

    return BasicTypes(
        int64_value=INT64_MIN, uint64_value=UINT64_MAX, int8_value=-128, bool_value=True
    )


def _time() -> object:
    from builtin_interfaces.msg import Time  # noqa: PLC0415

    return Time(sec=-5, nanosec=999_999_999)


EXACT = {"std_msgs/msg/String", "geometry_msgs/msg/Twist", "builtin_interfaces/msg/Time"}
"""Types without alignment padding: byte-identical."""
STAMP = {"sec": 1_700_000_000, "nanosec": 123_456_789}
CASES: dict[str, tuple[Callable[[], object], dict[str, object]]] = {
    "std_msgs/msg/String": (_string, {"data": "héllo foxglove"}),
    "sensor_msgs/msg/Image": (
        _image,
        {
            "header": {"stamp": STAMP, "frame_id": "camera"},
            "height": 2,
            "width": 3,
            "encoding": "rgb8",
            "is_bigendian": 0,
            "step": 9,
            "data": list(range(18)),
        },
    ),
    "geometry_msgs/msg/Twist": (
        _twist,
        {"linear": {"x": 1.5, "y": -2.25, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 3.0}},
    ),
    "test_msgs/msg/UnboundedSequences": (
        _arrays,
        {
            "int64_values": [INT64_MIN, 0, INT64_MAX],
            "uint64_values": [0, UINT64_MAX],
            "string_values": ["a", "", "ccc"],
            "float64_values": [0.5, -1e300],
            "bool_values": [True, False, True],
            "byte_values": [0, 255],
            "alignment_check": 7,
        },
    ),
    "test_msgs/msg/BasicTypes": (
        _basic,
        {
            "int64_value": INT64_MIN,
            "uint64_value": UINT64_MAX,
            "int8_value": -128,
            "bool_value": True,
        },
    ),
    "builtin_interfaces/msg/Time": (_time, {"sec": -5, "nanosec": 999_999_999}),
}


@pytest.mark.parametrize("type_name", sorted(CASES))
def test_message_data_is_rclpy_cdr(type_name: str) -> None:
    from rclpy.serialization import deserialize_message, serialize_message  # noqa: PLC0415

    build, as_dict = CASES[type_name]
    with warnings.catch_warnings():
        # rclpy's type support loads lark-parser 0.12, which imports the deprecated sre_parse
        warnings.simplefilter("ignore", DeprecationWarning)
        expected = bytes(serialize_message(build()))
    graph = Graph(TypeRegistry(Dialect.ROS2, [_share()]))
    publisher = graph.create_publisher("/t", type_name)
    session = FoxgloveSession(graph.port, "foxglove:t#1", session_id="s")
    channel = next(
        channel
        for frame in session.frames_to_send()
        if not frame.binary and b'"advertise"' in frame.data
        for channel in json.loads(frame.data)["channels"]
    )
    session.receive_frame(
        json.dumps(
            {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]}
        ).encode(),
        0.0,
        binary=False,
    )
    publisher.publish(graph.registry.message(type_name).from_python(as_dict))
    (frame,) = [frame for frame in session.frames_to_send() if frame.binary]
    message = frame.prefix + frame.data  # what the client gets in one message
    assert message[0] == 1 and struct.unpack_from("<I", message, 1) == (1,)
    payload = message[13:]
    # rclpy leaves alignment padding uninitialised (it differs from run to run); rosbags
    # writes zeros there: every other byte is the same, and rclpy reads ours back
    assert len(payload) == len(expected)
    assert all(ours in (theirs, 0) for ours, theirs in zip(payload, expected, strict=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        assert deserialize_message(payload, type(build())) == build()
    if type_name in EXACT:
        assert payload == expected


def _share() -> Path:
    """The ``share`` folder of the installed ROS 2 packages (test_msgs is not in rosbags)."""
    import test_msgs  # noqa: PLC0415

    for base in (Path(sys.prefix), *Path(test_msgs.__file__).parents):
        if (base / "share" / "test_msgs" / "msg").is_dir():
            return base / "share"
    pytest.skip("the test_msgs interface files are not installed")
