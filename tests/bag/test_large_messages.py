"""A 1 MB image in a bag written by rosbags reads back whole, in both formats.

Messages of 64 KiB and more reach rosbags' deserializer as a view
(``rwt_graph.types.wire.wire_input``), small ones as ``bytes``; both must give
the same values.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import Writer as Ros2Writer

from rwt_bag.reader import BagSource
from rwt_graph.types import Dialect, TypeRegistry

from .bags import typestore

PIXELS = (np.arange(1_000_000) % 251).astype(np.uint8)


def _image(ros1: bool) -> object:
    store = typestore(ros1)
    stamp = store.types["builtin_interfaces/msg/Time"](sec=7, nanosec=8)
    header_type = store.types["std_msgs/msg/Header"]
    header = (
        header_type(seq=3, stamp=stamp, frame_id="cam")
        if ros1
        else header_type(stamp=stamp, frame_id="cam")
    )
    return store.types["sensor_msgs/msg/Image"](
        header=header,
        height=1000,
        width=1000,
        encoding="mono8",
        is_bigendian=0,
        step=1000,
        data=PIXELS,
    )


@pytest.mark.parametrize("ros1", [True, False], ids=["ros1", "ros2"])
def test_a_1_mb_image_reads_back_whole(tmp_path: Path, ros1: bool) -> None:
    store = typestore(ros1)
    image = _image(ros1)
    if ros1:
        path = tmp_path / "big.bag"
        with Ros1Writer(path) as writer:
            conn = writer.add_connection("/camera", "sensor_msgs/msg/Image", typestore=store)
            writer.write(conn, 10, store.serialize_ros1(image, "sensor_msgs/msg/Image"))
    else:
        path = tmp_path / "big"
        with Ros2Writer(path, version=9) as writer:
            conn = writer.add_connection("/camera", "sensor_msgs/msg/Image", typestore=store)
            writer.write(conn, 10, store.serialize_cdr(image, "sensor_msgs/msg/Image"))
    source = BagSource([path], TypeRegistry(Dialect.ROS1 if ros1 else Dialect.ROS2))
    try:
        ((topic, _, msg, record),) = list(source.messages())
    finally:
        source.close()
    assert topic.topic == "/camera"
    assert len(record) > 1_000_000
    assert msg["data"] == PIXELS.tobytes()
    assert (msg["height"], msg["width"], msg["step"]) == (1000, 1000, 1000)
    assert msg["header"]["frame_id"] == "cam"
