"""The generated rosbags converters agree with interop's general walk (benchmarks B20).

It is the ``rosbags-converters`` shortcut (rwt_protocol.shortcuts): the
generated functions are built here whatever ``RWT_NO_SHORTCUTS`` says, so a run
without shortcuts still compares them with the general path.
"""

from __future__ import annotations

import numpy as np
import pytest
from types_support import DATA, NOW, same

from rwt_graph.types import Dialect, MessageType, TypeRegistry
from rwt_graph.types.convert import is_time_type, time_keys
from rwt_graph.types.interop import from_rosbags, to_rosbags
from rwt_graph.types.rosbagsfast import compile_from_rosbags, compile_to_rosbags
from rwt_graph.types.spec import ArrayKind, FieldType, is_bytes_base
from rwt_protocol.shortcuts import ENV_VAR


def _sample(ftype: FieldType, registry: TypeRegistry, depth: int = 0) -> object:
    """A value of ``ftype`` that is not its default (JSON-like, as a client sends)."""
    if ftype.array is not ArrayKind.NONE:
        count = 2 if ftype.array is ArrayKind.UNBOUNDED else min(2, ftype.length or 0)
        if ftype.array is ArrayKind.FIXED:
            count = ftype.length or 0
        if is_bytes_base(ftype.base):
            return [(7 * i + 3) % 256 for i in range(count)]
        return [_sample(ftype.element, registry, depth + 1) for _ in range(count)]
    if is_time_type(ftype):
        sec, nsec = time_keys(registry.dialect)
        return {sec: 12, nsec: 34}
    if ftype.is_message:
        return _message_sample(registry.message(ftype.base), registry, depth + 1)
    base = ftype.base
    if base == "wstring":  # beyond Latin-1 and beyond the BMP (a UTF-16 surrogate pair)
        return "é😀" if ftype.string_bound is None or ftype.string_bound >= 2 else "é"
    if base == "string":
        return "ab" if ftype.string_bound is None or ftype.string_bound >= 2 else "a"
    if base == "bool":
        return True
    if base in ("float32", "float64"):
        return 1.5
    return 1  # every integer kind, byte and char hold 1


def _message_sample(mtype: MessageType, registry: TypeRegistry, depth: int = 0) -> object:
    if depth > 6:  # no shipped type nests deeper; a guard against a cycle
        return {}
    return {spec.name: _sample(spec.type, registry, depth) for spec in mtype.fields}


def _serialize(registry: TypeRegistry, mtype: MessageType, obj: object) -> bytes:
    store = registry.typestore()
    if registry.dialect is Dialect.ROS1:
        return bytes(store.serialize_ros1(obj, mtype.rosbags_name))
    return bytes(store.serialize_cdr(obj, mtype.rosbags_name))


@pytest.mark.parametrize("dialect", [Dialect.ROS2, Dialect.ROS1])
def test_every_known_type_converts_alike_both_ways(dialect: Dialect) -> None:
    registry = TypeRegistry(dialect, [DATA])
    store = registry.typestore()
    resolve = registry.message
    checked = wide = 0
    for name in registry.message_names():
        mtype = registry.message(name)
        if mtype.rosbags_name not in store.types:
            continue  # a type the store could not load is not serializable either way
        to_fast = compile_to_rosbags(mtype, store, lambda n: _to(registry, n), resolve)
        from_fast = compile_from_rosbags(mtype, lambda n: _from(registry, n), resolve)
        for value in (mtype.default(now=NOW), _message_sample(mtype, registry)):
            msg = mtype.from_json(value, now=NOW).msg
            general_obj = to_rosbags(msg, mtype, store, resolve)
            fast_obj = to_fast(msg)
            assert _serialize(registry, mtype, fast_obj) == _serialize(
                registry, mtype, general_obj
            ), name
            # rosbags' own objects, as a bag reader gives them: numpy arrays
            raw = _serialize(registry, mtype, general_obj)
            if dialect is Dialect.ROS1:
                decoded = store.deserialize_ros1(raw, mtype.rosbags_name)
            else:
                decoded = store.deserialize_cdr(raw, mtype.rosbags_name)
            for obj in (decoded, general_obj):
                assert same(from_fast(obj), from_rosbags(obj, mtype, resolve)), name
        checked += 1
        wide += any(spec.type.base == "wstring" for spec in mtype.fields)
    assert checked > 100 and wide > 0


def _to(registry: TypeRegistry, name: str):  # type: ignore[no-untyped-def]
    mtype = registry.message(name)
    return compile_to_rosbags(
        mtype, registry.typestore(), lambda n: _to(registry, n), registry.message
    )


def _from(registry: TypeRegistry, name: str):  # type: ignore[no-untyped-def]
    return compile_from_rosbags(
        registry.message(name), lambda n: _from(registry, n), registry.message
    )


def test_bytes_become_views_and_views_become_bytes(ros2: TypeRegistry) -> None:
    """uint8[] stays one buffer: a view on the way out, bytes on the way back (no per-byte work)."""
    mtype = ros2.message("sensor_msgs/Image")
    data = bytes(range(256)) * 4
    msg = mtype.from_python({"height": 1, "width": 1024, "step": 1024, "data": data})
    obj = mtype.to_rosbags(msg, ros2.typestore())
    assert isinstance(obj.data, np.ndarray)  # type: ignore[attr-defined]
    assert obj.data.tobytes() == data  # type: ignore[attr-defined]
    back = mtype.plain_from_rosbags(obj)
    assert type(back["data"]) is bytes
    assert back["data"] == data


@pytest.mark.parametrize("switch", ["", "rosbags-converters"])
def test_message_type_uses_the_shortcut_unless_switched_off(
    switch: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(ENV_VAR, switch)
    registry = TypeRegistry(Dialect.ROS2, [DATA])
    mtype = registry.message("geometry_msgs/PoseStamped")
    convert = mtype.to_rosbags_converter(registry.typestore())
    generated = convert.__code__.co_filename.startswith("<rwt to-rosbags converter")
    assert generated is (switch == "")
    generated = mtype.from_rosbags_converter().__code__.co_filename.startswith("<rwt from-rosbags")
    assert generated is (switch == "")
    msg = mtype.from_python({"header": {"frame_id": "map"}, "pose": {"position": {"x": 2.0}}})
    obj = mtype.to_rosbags(msg, registry.typestore())
    assert mtype.plain_from_rosbags(obj) == from_rosbags(obj, mtype, registry.message)
