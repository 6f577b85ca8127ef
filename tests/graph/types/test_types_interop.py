"""Sources, definition texts and rosbags interop (REF §3.5, §7.1 L59)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from types_support import DATA, NOW, same

from rwt_graph.types import ArrayKind, Constant, Dialect, FieldSpec, FieldType, TypeRegistry
from rwt_graph.types.sources import render_text
from rwt_protocol.errors import FieldError

RULE = "=" * 80


def test_user_interface_dirs_override_packaged_and_store_types(ros2: TypeRegistry) -> None:
    # tests/graph/data/interfaces/geometry_msgs/msg/Point.msg: "float64 x 7" and no default for y, z
    point = ros2.message("geometry_msgs/Point")
    assert point.default() == {"x": 7.0, "y": 0.0, "z": 0.0}
    assert TypeRegistry().message("geometry_msgs/Point").default()["x"] == 0.0


def test_first_interface_dir_wins(tmp_path: Path) -> None:
    for folder, text in (("first", "int32 a\n"), ("second", "string b\n")):
        msg = tmp_path / folder / "pkg" / "msg"
        msg.mkdir(parents=True)
        (msg / "T.msg").write_text(text)
    registry = TypeRegistry(
        interface_dirs=[tmp_path / "first", tmp_path / "second", tmp_path / "x"]
    )
    assert [spec.name for spec in registry.message("pkg/T").fields] == ["a"]


def test_definition_text_of_file_and_store_types(ros2: TypeRegistry) -> None:
    assert ros2.message("rwt_test_msgs/Inner").definition_text() == (
        "std_msgs/Header[2] pair\nbuiltin_interfaces/Duration span\n"
    )
    assert ros2.message("std_msgs/String").definition_text() == "string data\n"
    status = ros2.message("sensor_msgs/NavSatStatus").definition_text()
    assert status.startswith("int8 STATUS_UNKNOWN=-2\n")
    # in the .msg file's order: each field after its constants (test_declaration_order.py)
    assert "int8 STATUS_GBAS_FIX=2\nint8 status\nuint16 SERVICE_UNKNOWN=0\n" in status
    assert status.endswith("uint16 SERVICE_GALILEO=8\nuint16 service\n")
    assert ros2.message("std_msgs/Empty").definition_text() == ""
    assert ros2.message("std_msgs/Empty").fields == ()


def test_full_text_follows_the_gendeps_layout(ros2: TypeRegistry, ros1: TypeRegistry) -> None:
    assert ros2.message("std_msgs/String").full_text() == "string data\n"
    text = ros2.message("geometry_msgs/PoseStamped").full_text()
    chunks = text.split(RULE + "\n")
    assert chunks[0] == "std_msgs/Header header\ngeometry_msgs/Pose pose\n"
    assert [chunk.splitlines()[0] for chunk in chunks[1:]] == [
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
        "MSG: geometry_msgs/Pose",
        "MSG: geometry_msgs/Point",
        "MSG: geometry_msgs/Quaternion",
    ]
    assert chunks[2] == "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    assert "float64 w 1" in chunks[5]
    # ROS 1: Noetic's texts, comments included, joined as genmsg joins them (each
    # file's own last newline, then one more): what `rosbag check` compares
    ros1_text = ros1.message("std_msgs/Header").full_text()
    assert ros1_text.startswith("# Standard metadata for higher-level stamped data types.\n")
    assert ros1_text.endswith("#Frame this data is associated with\nstring frame_id\n")
    pose = ros1.message("geometry_msgs/PoseStamped").full_text()
    assert pose.startswith("# A Pose with reference coordinate frame and timestamp\nHeader")
    assert f"Pose pose\n\n{RULE}\nMSG: std_msgs/Header\n# Standard metadata" in pose


def test_typestore_serializes_shipped_file_and_service_types(ros2: TypeRegistry) -> None:
    store = ros2.typestore()
    assert store is ros2.typestore()
    limits = ros2.message("rwt_test_msgs/Limits")
    msg = limits.from_json({"uuid": list(range(16)), "octets": [255], "tags": ["a"]}, now=NOW).msg
    obj = limits.to_rosbags(msg, store)
    raw = store.serialize_cdr(obj, limits.rosbags_name)
    back = store.deserialize_cdr(raw, limits.rosbags_name)
    assert same(limits.from_python(back), msg)
    request = ros2.service("rwt_test_msgs/AddInts").request
    raw = store.serialize_cdr(request.to_rosbags({"a": 2, "b": -3}, store), request.rosbags_name)
    assert request.from_python(store.deserialize_cdr(raw, request.rosbags_name)) == {
        "a": 2,
        "b": -3,
    }
    assert "rwt_test_msgs/action/Count_Feedback" in store.fielddefs
    assert "sensor_msgs/msg/Image" in store.fielddefs


def test_typestore_serializes_ros1(ros1: TypeRegistry) -> None:
    store = ros1.typestore()
    stamped = ros1.message("rwt_test_msgs/Stamped")
    msg = stamped.from_json({"header": {"seq": 9, "frame_id": "f"}}, now=NOW).msg
    raw = store.serialize_ros1(stamped.to_rosbags(msg, store), stamped.rosbags_name)
    back = stamped.from_python(store.deserialize_ros1(raw, stamped.rosbags_name))
    assert back == msg
    assert back["header"] == {
        "seq": 9,
        "stamp": {"secs": 1_700_000_000, "nsecs": 250_000_000},
        "frame_id": "f",
    }


def test_from_python_takes_rosbags_objects_and_dicts(ros2: TypeRegistry) -> None:
    store = ros2.typestore()
    types = store.types
    image = types["sensor_msgs/msg/Image"](
        header=types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="cam"
        ),
        height=1,
        width=2,
        encoding="mono8",
        is_bigendian=0,
        step=2,
        data=np.array([7, 255], dtype=np.uint8),
    )
    mtype = ros2.message("sensor_msgs/Image")
    msg = mtype.from_python(image)
    assert msg == {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "cam"},
        "height": 1,
        "width": 2,
        "encoding": "mono8",
        "is_bigendian": 0,
        "step": 2,
        "data": b"\x07\xff",
    }
    assert mtype.from_python({"height": 3})["header"]["stamp"] == {"sec": 0, "nanosec": 0}  # type: ignore[index]
    assert mtype.from_python({}, now=NOW)["header"]["stamp"]["sec"] == 1_700_000_000  # type: ignore[index]
    with pytest.raises(
        FieldError, match=r"expected object \(type sensor_msgs/msg/Image\), got std_msgs"
    ):
        mtype.from_python(types["std_msgs/msg/String"](data="x"))
    with pytest.raises(FieldError, match=r"got 4294967296 at \$.height"):
        mtype.from_python({"height": 2**32})
    octets = types["std_msgs/msg/ByteMultiArray"](
        layout=types["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0),
        data=np.array([-1, 5], dtype=np.int8),
    )
    assert ros2.message("std_msgs/ByteMultiArray").from_python(octets)["data"] == [255, 5]


def test_packaged_folders_are_optional_and_data_dir_exists() -> None:
    assert DATA.is_dir()
    assert TypeRegistry(Dialect.ROS1, [DATA / "missing"]).message("std_msgs/String").name == (
        "std_msgs/String"
    )


def test_empty_messages_and_scalar_octets_serialize(ros2: TypeRegistry) -> None:
    store = ros2.typestore()
    nothing = ros2.service("rwt_test_msgs/Nothing").request
    assert nothing.fields == ()
    raw = store.serialize_cdr(nothing.to_rosbags({}, store), nothing.rosbags_name)
    assert nothing.from_python(store.deserialize_cdr(raw, nothing.rosbags_name)) == {}
    empty = ros2.message("std_msgs/Empty")
    raw = store.serialize_cdr(empty.to_rosbags({}, store), empty.rosbags_name)
    assert empty.from_python(store.deserialize_cdr(raw, empty.rosbags_name)) == {}
    byte = ros2.message("std_msgs/Byte")
    raw = store.serialize_cdr(byte.to_rosbags({"data": 200}, store), byte.rosbags_name)
    assert byte.from_python(store.deserialize_cdr(raw, byte.rosbags_name)) == {"data": 200}
    assert byte.from_python(store.types["std_msgs/msg/Byte"](data=-56)) == {"data": 200}
    floats = store.types["std_msgs/msg/Float32"](data=np.float32(1.5))
    assert ros2.message("std_msgs/Float32").from_python(floats) == {"data": 1.5}


def test_rosbags_objects_with_python_sequences(ros2: TypeRegistry) -> None:
    types = ros2.typestore().types
    layout = types["std_msgs/msg/MultiArrayLayout"](
        dim=[types["std_msgs/msg/MultiArrayDimension"](label="x", size=2, stride=2)],
        data_offset=0,
    )
    array = types["std_msgs/msg/UInt8MultiArray"](layout=layout, data=b"\x01\x02")
    msg = ros2.message("std_msgs/UInt8MultiArray").from_python(array)
    assert msg["data"] == b"\x01\x02"
    assert msg["layout"]["dim"] == [{"label": "x", "size": 2, "stride": 2}]  # type: ignore[index]


def test_render_text_of_literals() -> None:
    fields = [
        FieldSpec("raw", FieldType("uint8", array=ArrayKind.UNBOUNDED), b"\x01\x02"),
        FieldSpec("on", FieldType("bool", array=ArrayKind.FIXED, length=2), [True, False]),
    ]
    text = render_text(fields, [Constant("YES", "bool", True)], Dialect.ROS2)
    assert text == "bool YES=true\nuint8[] raw [1, 2]\nbool[2] on [true, false]"


def test_repr_and_cached_flags(ros2: TypeRegistry) -> None:
    mtype = ros2.message("geometry_msgs/PoseStamped")
    assert repr(mtype) == "MessageType('geometry_msgs/msg/PoseStamped')"
    assert mtype.has_header and mtype.has_header
    assert mtype.compiled() is mtype.compiled()


def test_ros1_falls_back_to_ros2_store_types(ros1: TypeRegistry) -> None:
    log = ros1.message("rcl_interfaces/msg/Log")
    assert log.name == "rcl_interfaces/Log"
    assert log.default()["stamp"] == {"secs": 0, "nsecs": 0}
    assert "rcl_interfaces/Log" in ros1.message_names()
    store = ros1.typestore()
    msg = log.from_json({"msg": "hi", "stamp": "now"}, now=NOW).msg
    raw = store.serialize_ros1(log.to_rosbags(msg, store), log.rosbags_name)
    assert log.from_python(store.deserialize_ros1(raw, log.rosbags_name)) == msg


def test_typestore_leaves_out_types_that_fail_to_load(tmp_path: Path) -> None:
    for kind, name, text in (
        ("msg", "Good.msg", "int32 a\n"),
        ("msg", "Dangling.msg", "Missing m\n"),
        ("srv", "Broken.srv", "int32 a\n"),
        ("action", "Broken.action", "int32 a\n---\nint32 b\n"),
    ):
        folder = tmp_path / "pkg" / kind
        folder.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
    registry = TypeRegistry(interface_dirs=[tmp_path])
    store = registry.typestore()
    assert "pkg/msg/Good" in store.fielddefs
    assert "pkg/msg/Dangling" not in store.fielddefs
    assert not any(
        key.startswith("pkg/srv/") or key.startswith("pkg/action/") for key in store.fielddefs
    )
