"""Registries share a rosbags typestore when, and only when, their definitions are the same."""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt_graph.types import Dialect, TypeRegistry, codec_for

if TYPE_CHECKING:
    from pathlib import Path


def test_the_same_definitions_share_one_store() -> None:
    first, second = TypeRegistry(), TypeRegistry()
    assert first.typestore() is second.typestore()
    assert TypeRegistry(Dialect.ROS1).typestore() is not first.typestore()


def test_a_definition_of_its_own_gets_a_store_of_its_own(tmp_path: Path) -> None:
    (tmp_path / "pkg" / "msg").mkdir(parents=True)
    (tmp_path / "pkg" / "msg" / "Point.msg").write_text("float64 x\nint32 count\n")
    own = TypeRegistry(interface_dirs=[tmp_path])
    assert own.typestore() is not TypeRegistry().typestore()
    point = own.message("pkg/msg/Point")
    data = own.serialize(point, point.from_python({"x": 1.5, "count": -3}))
    assert len(data) == 4 + 8 + 4  # CDR header, float64, int32
    assert codec_for(own, point).deserialize(data) == {"x": 1.5, "count": -3}

    # the same file again, changed: not the store of the first
    (tmp_path / "pkg" / "msg" / "Point.msg").write_text("float32 x\nint32 count\n")
    changed = TypeRegistry(interface_dirs=[tmp_path])
    assert changed.typestore() is not own.typestore()
    point = changed.message("pkg/msg/Point")
    data = changed.serialize(point, point.from_python({"x": 1.5, "count": 2}))
    assert len(data) == 4 + 4 + 4  # CDR header, float32, int32
    assert codec_for(changed, point).deserialize(data) == {"x": 1.5, "count": 2}
