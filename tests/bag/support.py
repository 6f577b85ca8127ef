"""Helpers of the record-and-replay tests: rosbags objects as plain values, test messages."""

from __future__ import annotations

import base64
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from rwt_protocol.shortcuts import enabled

PIXELS = bytes(range(256)) * 4
#: RWT_NO_SHORTCUTS=bag-checkpoints writes with rosbags' Writer, whose bag is
#: readable only once closed: a test of a bag read before that is the shortcut's.
CHECKPOINTS = pytest.mark.skipif(
    not enabled("bag-checkpoints"), reason="the bag-checkpoints shortcut is switched off"
)

#: Client code (format braces doubled): wait, by asking rosapi, until the recorder's
#: node is (``on``) or is no longer (not ``on``) a subscriber of ``topic``: the recorder
#: subscribes to new topics at its next look (every 0.2 s), and lets go of all when it stops.
RECORDER = """
    def recorder(ros, topic, on):
        subscribers = roslibpy.Service(ros, "/rosapi/subscribers", "rosapi/Subscribers")
        for _ in range(400):
            request = roslibpy.ServiceRequest({{"topic": topic}})
            if ("/rwt_recorder" in subscribers.call(request, timeout=10)["subscribers"]) == on:
                return
            time.sleep(0.05)
        raise SystemExit("the recorder %s %s" % ("never took" if on else "kept", topic))
"""


def plain(value: Any) -> Any:
    """A rosbags message as dicts, lists and bytes (uint8 arrays), for comparison."""
    if dataclasses.is_dataclass(value):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, np.ndarray):
        return value.tobytes() if value.dtype == np.uint8 else value.tolist()
    if isinstance(value, list):
        return [plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_bag(path: Path) -> dict[str, list[Any]]:
    """Every message of a bag by topic, read with rosbags' own reader, as plain values."""
    found: dict[str, list[Any]] = {}
    with AnyReader([path]) as reader:
        for conn, _, raw in reader.messages():
            found.setdefault(conn.topic, []).append(plain(reader.deserialize(raw, conn.msgtype)))
    return found


def stamp(ros1: bool, sec: int, nanosec: int) -> dict[str, int]:
    """A time in the dialect's JSON spelling (REF §4.1)."""
    return {"secs": sec, "nsecs": nanosec} if ros1 else {"sec": sec, "nanosec": nanosec}


def sample_messages(ros1: bool) -> list[tuple[str, str, dict[str, Any]]]:
    """(topic, type, JSON message) of arrays, nested types, times and non-ASCII strings."""
    header = {"stamp": stamp(ros1, 1_700_000_000, 123_456_789), "frame_id": "bäse_链接"}
    if ros1:
        header = {"seq": 7, **header}
    return [
        ("/rt/string", "std_msgs/String", {"data": "héllo wörld ✓ 日本語"}),
        (
            "/rt/joints",
            "sensor_msgs/JointState",
            {
                "header": header,
                "name": ["shoulder", "ぐるぐる", ""],
                "position": [1.5, -2.25, 1e-300],
                "velocity": [],
                "effort": [0.125, 3.0, -0.0],
            },
        ),
        (
            "/rt/pose",
            "geometry_msgs/PoseStamped",
            {
                "header": header,
                "pose": {
                    "position": {"x": 1.0, "y": -2.5, "z": 3.25},
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.7071067811865476, "w": 0.5},
                },
            },
        ),
        (
            "/rt/image",
            "sensor_msgs/Image",
            {
                "header": header,
                "height": 4,
                "width": 256,
                "encoding": "mono8",
                "is_bigendian": 0,
                "step": 256,
                "data": base64.b64encode(PIXELS).decode(),
            },
        ),
        (
            "/rt/multi",
            "std_msgs/Float64MultiArray",
            {
                "layout": {
                    "dim": [
                        {"label": "rows", "size": 2, "stride": 6},
                        {"label": "cöls", "size": 3, "stride": 3},
                    ],
                    "data_offset": 1,
                },
                "data": [0.5, 1.5, 2.5, -3.5, 4.0, 5e10],
            },
        ),
    ]


def expected(msg: Any) -> Any:
    """A JSON message as rosbags reads it back: times as sec/nanosec, images as bytes."""
    if isinstance(msg, dict):
        if set(msg) == {"secs", "nsecs"}:
            return {"sec": msg["secs"], "nanosec": msg["nsecs"]}
        return {
            k: (PIXELS if k == "data" and v == base64.b64encode(PIXELS).decode() else expected(v))
            for k, v in msg.items()
        }
    if isinstance(msg, list):
        return [expected(v) for v in msg]
    return msg
