"""rclpy's own serialization is read everywhere rwt reads CDR, trailing bytes and all.

rclpy's ``serialize_message`` of a ``sensor_msgs/JointState`` carries 8 bytes
past its fields (rosbags itself refuses more than 3 bytes of padding): the link
(services cross through it), the Zenoh link and the bag reader take the
fields and ignore the rest.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer

from rwt_bag.reader import BagSource
from rwt_graph.types import Dialect, TypeRegistry
from rwt_graph.types.wire import CdrError, read_cdr
from rwt_ros2.codec import decode
from rwt_zenoh.payload import decode_message

from .support import skip_without_rclpy

pytestmark = skip_without_rclpy()


@pytest.fixture(scope="module")
def joint_state_cdr() -> bytes:
    from rclpy.serialization import serialize_message  # noqa: PLC0415
    from sensor_msgs.msg import JointState  # noqa: PLC0415

    with warnings.catch_warnings():
        # rclpy's type support loads lark-parser 0.12, which imports the deprecated sre_parse
        warnings.simplefilter("ignore", DeprecationWarning)
        data = serialize_message(JointState(name=["elbow"], position=[0.25], effort=[2.0]))
    registry = TypeRegistry(Dialect.ROS2)
    written = registry.serialize(
        registry.message("sensor_msgs/msg/JointState"),
        {
            "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
            "name": ["elbow"],
            "position": [0.25],
            "velocity": [],
            "effort": [2.0],
        },
    )
    assert len(data) - len(written) > 3  # more than rosbags' padding allowance
    return bytes(data)


def _check(msg: dict[str, object]) -> None:
    assert msg["name"] == ["elbow"]
    assert list(msg["position"]) == [0.25]  # type: ignore[call-overload]
    assert list(msg["effort"]) == [2.0]  # type: ignore[call-overload]


def test_the_ros2_link_reads_it(joint_state_cdr: bytes) -> None:
    registry = TypeRegistry(Dialect.ROS2)
    _check(decode(registry, registry.message("sensor_msgs/msg/JointState"), joint_state_cdr))


def test_the_zenoh_link_reads_it(joint_state_cdr: bytes) -> None:
    registry = TypeRegistry(Dialect.ROS2)
    mtype = registry.message("sensor_msgs/msg/JointState")
    _check(decode_message(registry, mtype, joint_state_cdr))


def test_the_bag_reader_reads_it(joint_state_cdr: bytes, tmp_path: Path) -> None:
    registry = TypeRegistry(Dialect.ROS2)
    path = tmp_path / "joints"
    with Ros2Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(
            "/joint_states", "sensor_msgs/msg/JointState", typestore=registry.typestore()
        )
        writer.write(conn, 1_000, joint_state_cdr)
    source = BagSource([path], registry)
    try:
        [(_, _, msg, record)] = list(source.messages())
    finally:
        source.close()
    assert record == joint_state_cdr  # replayed as the bag holds it
    _check(msg)


def test_a_short_payload_is_still_refused(joint_state_cdr: bytes) -> None:
    registry = TypeRegistry(Dialect.ROS2)
    with pytest.raises(CdrError):
        read_cdr(registry.typestore(), joint_state_cdr[:20], "sensor_msgs/msg/JointState")
    with pytest.raises(CdrError):
        read_cdr(
            registry.typestore(), b"\x07\x07" + joint_state_cdr[2:], "sensor_msgs/msg/JointState"
        )


def test_far_more_bytes_than_the_payload_are_refused(joint_state_cdr: bytes) -> None:
    registry = TypeRegistry(Dialect.ROS2)
    with pytest.raises(CdrError, match="bytes after a payload"):
        read_cdr(registry.typestore(), joint_state_cdr + bytes(4096), "sensor_msgs/msg/JointState")
