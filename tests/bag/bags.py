"""Bags written by rosbags' own writers (not by rwt), with standard types, for replay tests.

Every bag holds the same messages, at these times after ``T0``:

    /tf_static  tf2_msgs/TFMessage     0.00            (two transforms; no QoS in the bag)
    /map        nav_msgs/OccupancyGrid 0.01            (3 x 2 cells)
    /chatter    std_msgs/String        0.10 + 0.05 i   i < CHATTER ("chatter i ✓")
    /tf         tf2_msgs/TFMessage     0.12 + 0.10 i   i < 10
    /camera     sensor_msgs/Image      0.20 + 0.30 i   i < 3 (8 x 4 rgb8)
    /points     sensor_msgs/PointCloud2 0.30, 0.80     (3 points x, y, z float32)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

T0 = 1_700_000_000 * 10**9
CHATTER = 20
CHATTER_GAP_S = 0.05
IMAGE = bytes(range(96))  # 8 x 4 pixels of rgb8
POINTS = np.array([[1.0, 2.0, 3.0], [-1.5, 0.25, 8.0], [0.0, 0.0, -2.0]], dtype=np.float32)
MAP = [0, 100, -1, 50, 0, 100]

TF_MESSAGE_ROS1 = "geometry_msgs/TransformStamped[] transforms\n"


def typestore(ros1: bool) -> Typestore:
    """rosbags' store of the dialect (Noetic lacks tf2_msgs: it is added from its text)."""
    if not ros1:
        return get_typestore(Stores.ROS2_JAZZY)
    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg(TF_MESSAGE_ROS1, "tf2_msgs/msg/TFMessage"))
    return store


def _header(store: Typestore, ros1: bool, ns: int, frame: str) -> object:
    t = store.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    cls = store.types["std_msgs/msg/Header"]
    return cls(seq=0, stamp=t, frame_id=frame) if ros1 else cls(stamp=t, frame_id=frame)


def _tf(store: Typestore, ros1: bool, ns: int, pairs: list[tuple[str, str, float]]) -> object:
    types = store.types
    transforms = [
        types["geometry_msgs/msg/TransformStamped"](
            header=_header(store, ros1, ns, parent),
            child_frame_id=child,
            transform=types["geometry_msgs/msg/Transform"](
                translation=types["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0),
                rotation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        )
        for parent, child, x in pairs
    ]
    return types["tf2_msgs/msg/TFMessage"](transforms=transforms)


def messages(store: Typestore, ros1: bool) -> list[tuple[str, str, int, object]]:
    """(topic, type, bag time ns, rosbags message) in time order."""
    types = store.types
    ms = 10**6
    out: list[tuple[str, str, int, object]] = []
    static = [("map", "odom", 1.0), ("base_link", "laser", 0.25)]
    out.append(("/tf_static", "tf2_msgs/msg/TFMessage", T0, _tf(store, ros1, T0, static)))
    info = types["nav_msgs/msg/MapMetaData"](
        map_load_time=types["builtin_interfaces/msg/Time"](sec=1, nanosec=2),
        resolution=0.5,
        width=3,
        height=2,
        origin=types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=-1.0, y=-2.0, z=0.0),
            orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        ),
    )
    grid = types["nav_msgs/msg/OccupancyGrid"](
        header=_header(store, ros1, T0 + 10 * ms, "map"),
        info=info,
        data=np.array(MAP, dtype=np.int8),
    )
    out.append(("/map", "nav_msgs/msg/OccupancyGrid", T0 + 10 * ms, grid))
    for i in range(CHATTER):
        ns = T0 + 100 * ms + int(i * CHATTER_GAP_S * 1e9)
        out.append(
            (
                "/chatter",
                "std_msgs/msg/String",
                ns,
                types["std_msgs/msg/String"](data=f"chatter {i} ✓"),
            )
        )
    for i in range(10):
        ns = T0 + 120 * ms + i * 100 * ms
        out.append(
            (
                "/tf",
                "tf2_msgs/msg/TFMessage",
                ns,
                _tf(store, ros1, ns, [("odom", "base_link", i / 10)]),
            )
        )
    for i in range(3):
        ns = T0 + 200 * ms + i * 300 * ms
        image = types["sensor_msgs/msg/Image"](
            header=_header(store, ros1, ns, "camera"),
            height=4,
            width=8,
            encoding="rgb8",
            is_bigendian=0,
            step=24,
            data=np.frombuffer(IMAGE, dtype=np.uint8),
        )
        out.append(("/camera", "sensor_msgs/msg/Image", ns, image))
    field = types["sensor_msgs/msg/PointField"]
    fields = [field(name=n, offset=4 * k, datatype=7, count=1) for k, n in enumerate("xyz")]
    for ns in (T0 + 300 * ms, T0 + 800 * ms):
        cloud = types["sensor_msgs/msg/PointCloud2"](
            header=_header(store, ros1, ns, "laser"),
            height=1,
            width=3,
            fields=fields,
            is_bigendian=False,
            point_step=12,
            row_step=36,
            data=np.frombuffer(POINTS.tobytes(), dtype=np.uint8),
            is_dense=True,
        )
        out.append(("/points", "sensor_msgs/msg/PointCloud2", ns, cloud))
    return sorted(out, key=lambda m: m[2])


def write_bag(path: Path, fmt: str) -> Path:
    """Write the bag with rosbags: ``fmt`` is mcap, sqlite3 or ros1 (then ``path`` gets .bag)."""
    ros1 = fmt == "ros1"
    store = typestore(ros1)
    msgs = messages(store, ros1)
    if ros1:
        path = path.with_suffix(".bag")
        with Ros1Writer(path) as writer:
            conns: dict[str, object] = {}
            for topic, msgtype, ns, msg in msgs:
                if topic not in conns:
                    conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
                writer.write(conns[topic], ns, store.serialize_ros1(msg, msgtype))
        return path
    plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
    with Ros2Writer(path, version=9, storage_plugin=plugin) as writer:
        conns = {}
        for topic, msgtype, ns, msg in msgs:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], ns, store.serialize_cdr(msg, msgtype))
    return path
