"""The messages of the scenarios, built so that their frames have a fixed size.

Each publish op carries a sequence number (zero-padded, so every frame of a
scenario has the same length) and is written exactly as rwt writes the op it
delivers (compact JSON, ``op``/``topic``/``msg`` first, every field in
declaration order, floats in shortest form; CBOR with the same key order), so
a subscriber of either server can expect the very bytes the publisher sent.
"""

from __future__ import annotations

import cbor2

__all__ = [
    "advertise",
    "image_cbor",
    "image_json_msg",
    "publish_json",
    "string_publish",
    "subscribe",
    "twist_publish",
]

SEQ_DIGITS = 8


def subscribe(topic: str, type_name: str, compression: str = "none") -> bytes:
    """A ``subscribe`` op payload (JSON)."""
    extra = "" if compression == "none" else f',"compression":"{compression}"'
    return f'{{"op":"subscribe","topic":"{topic}","type":"{type_name}"{extra}}}'.encode()


def advertise(topic: str, type_name: str) -> bytes:
    """An ``advertise`` op payload (JSON)."""
    return f'{{"op":"advertise","topic":"{topic}","type":"{type_name}"}}'.encode()


def publish_json(topic: str, msg_json: bytes) -> bytes:
    """A ``publish`` op around an already-encoded message, as rwt writes it."""
    return b'{"op":"publish","topic":"' + topic.encode() + b'","msg":' + msg_json + b"}"


def string_publish(topic: str, seq: int, size: int = 100) -> bytes:
    """A ``std_msgs/String`` publish op of exactly ``size`` bytes (at least ~60)."""
    head = publish_json(topic, b'{"data":""}')
    pad = size - len(head) - SEQ_DIGITS
    if pad < 0:
        raise ValueError(f"a publish on {topic} needs at least {len(head) + SEQ_DIGITS} bytes")
    data = f"{seq:0{SEQ_DIGITS}d}" + "x" * pad
    return publish_json(topic, b'{"data":"' + data.encode() + b'"}')


def twist_publish(topic: str, seq: int) -> bytes:
    """A ``geometry_msgs/Twist`` publish op; every value has a fixed width."""
    x = 100000000 + seq % 100000000 + 0.5
    msg = f'{{"linear":{{"x":{x!r},"y":0.25,"z":-0.5}},"angular":{{"x":0.125,"y":-0.75,"z":1.5}}}}'
    return publish_json(topic, msg.encode())


def image_cbor(topic: str, seq: int, width: int, height: int, encoding: str = "mono8") -> bytes:
    """A ``sensor_msgs/Image`` publish op as CBOR (the data a byte string)."""
    channels = 3 if encoding == "rgb8" else 1
    return cbor2.dumps(
        {"op": "publish", "topic": topic, "msg": image_msg(seq, width, height, encoding, channels)}
    )


def image_msg(seq: int, width: int, height: int, encoding: str, channels: int) -> dict[str, object]:
    """The internal form of an image whose data starts with the sequence number."""
    size = width * height * channels
    tag = f"{seq:0{SEQ_DIGITS}d}".encode()
    data = tag + bytes(range(256)) * ((size - len(tag)) // 256 + 1)
    return {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "camera"},
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": width * channels,
        "data": data[:size],
    }


def image_json_msg(seq: int, width: int, height: int, encoding: str = "rgb8") -> bytes:
    """The JSON of an image message (its data base64, as rosbridge sends ``uint8[]``)."""
    import msgspec  # noqa: PLC0415

    channels = 3 if encoding == "rgb8" else 1
    return msgspec.json.encode(image_msg(seq, width, height, encoding, channels))


def cloud_msg(seq: int, points: int) -> dict[str, object]:
    """A ``sensor_msgs/PointCloud2`` of ``points`` x/y/z/intensity float32 points."""
    size = points * 16
    tag = f"{seq:0{SEQ_DIGITS}d}".encode()
    data = (tag + bytes(range(256)) * (size // 256 + 1))[:size]
    fields = [
        {"name": name, "offset": 4 * i, "datatype": 7, "count": 1}
        for i, name in enumerate(("x", "y", "z", "intensity"))
    ]
    return {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "lidar"},
        "height": 1,
        "width": points,
        "fields": fields,
        "is_bigendian": False,
        "point_step": 16,
        "row_step": size,
        "data": data,
        "is_dense": True,
    }


def cloud_publish(topic: str, seq: int, points: int, *, binary: bool) -> bytes:
    """A point cloud publish op as CBOR (``binary``) or JSON (data in base64)."""
    import msgspec  # noqa: PLC0415

    op = {"op": "publish", "topic": topic, "msg": cloud_msg(seq, points)}
    return cbor2.dumps(op) if binary else msgspec.json.encode(op)


def grid_cbor(topic: str, seq: int, width: int = 1100, height: int = 1000) -> bytes:
    """A ``nav_msgs/OccupancyGrid`` publish op as CBOR, its data an int8 typed array."""
    cells = width * height
    tag = f"{seq:0{SEQ_DIGITS}d}".encode()
    data = (tag + bytes(range(0, 100)) * (cells // 100 + 1))[:cells]
    msg = {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "map"},
        "info": {
            "map_load_time": {"sec": 1, "nanosec": 0},
            "resolution": 0.05,
            "width": width,
            "height": height,
            "origin": {
                "position": {"x": 0.0, "y": 0.0, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            },
        },
        "data": cbor2.CBORTag(72, data),
    }
    return cbor2.dumps({"op": "publish", "topic": topic, "msg": msg})
