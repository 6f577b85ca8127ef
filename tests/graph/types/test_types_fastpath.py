"""The generated fast converter agrees with the general one, or steps aside (benchmarks B14).

It is the ``generated-converters`` shortcut (rwt_protocol.shortcuts): these
tests build their registries with it on whatever ``RWT_NO_SHORTCUTS`` says, so
that a run without shortcuts still compares it with the general path.
"""

from __future__ import annotations

import math

import msgspec
import pytest
from types_support import DATA, NOW

from rwt_graph.types import Dialect, TypeRegistry
from rwt_graph.types.convert import Context
from rwt_graph.types.message import _no_fast
from rwt_protocol.shortcuts import ENV_VAR


def _registry(dialect: Dialect, switch: str | None) -> TypeRegistry:
    """A registry whose every message type was built with ``RWT_NO_SHORTCUTS=switch``."""
    with pytest.MonkeyPatch.context() as patch:
        if switch is None:
            patch.delenv(ENV_VAR, raising=False)
        else:
            patch.setenv(ENV_VAR, switch)
        registry = TypeRegistry(dialect, [DATA])
        for name in registry.message_names():  # types choose when built: build them all now
            registry.message(name).fast_converter()
    return registry


@pytest.fixture(scope="module")
def ros2() -> TypeRegistry:
    return _registry(Dialect.ROS2, None)


@pytest.fixture(scope="module")
def ros1() -> TypeRegistry:
    return _registry(Dialect.ROS1, None)


def _general(registry: TypeRegistry, name: str, value: object) -> tuple[object, list[str]]:
    ctx = Context(NOW)
    msg = registry.message(name).compiled()[0](value, "$", ctx)
    return msg, ctx.missing


@pytest.mark.parametrize("dialect", ["ros2", "ros1"])
def test_every_known_type_converts_alike_on_both_paths(
    dialect: str, request: pytest.FixtureRequest
) -> None:
    registry: TypeRegistry = request.getfixturevalue(dialect)
    with_fast = 0
    for name in registry.message_names():
        mtype = registry.message(name)
        # A complete value as a client sends it: the default, through JSON.
        value = msgspec.json.decode(msgspec.json.encode(mtype.default(now=NOW)))
        fast = mtype.fast(value)
        general, missing = _general(registry, name, value)
        assert missing == [], name
        if fast is not None:
            with_fast += 1
            assert fast == general, name
            assert list(fast) == list(general), name  # declaration order kept
        assert mtype.from_json(value, now=NOW).msg == general, name
    assert with_fast > 0.8 * len(registry.message_names())


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("std_msgs/msg/String", {"data": "hi"}),
        (
            "geometry_msgs/msg/Twist",
            {"linear": {"x": 1.0, "y": 0.0, "z": -2.5}, "angular": {"x": 0.0, "y": 0.0, "z": 0.5}},
        ),
        ("std_msgs/msg/Header", {"stamp": {"sec": 5, "nanosec": 7}, "frame_id": "map"}),
        (
            "sensor_msgs/msg/Image",
            {
                "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "c"},
                "height": 1,
                "width": 2,
                "encoding": "mono8",
                "is_bigendian": 0,
                "step": 2,
                "data": "AAE=",
            },
        ),
        (
            "std_msgs/msg/Float32MultiArray",
            {
                "layout": {"dim": [{"label": "x", "size": 2, "stride": 2}], "data_offset": 0},
                "data": [1.5, -2.0],
            },
        ),
    ],
)
def test_complete_well_typed_values_take_the_fast_path(
    ros2: TypeRegistry, name: str, value: dict[str, object]
) -> None:
    fast = ros2.message(name).fast(value)
    assert fast is not None
    assert fast == _general(ros2, name, value)[0]


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("std_msgs/msg/String", {}),  # missing field: defaults and a warning (D7)
        ("std_msgs/msg/String", {"data": "a", "extra": 1}),  # unknown field: an error
        ("std_msgs/msg/String", {"data": 5}),  # wrong kind: an error text
        ("std_msgs/msg/String", ["data"]),
        ("std_msgs/msg/Float64", {"data": 1}),  # an int for a float: converted to 1.0
        ("std_msgs/msg/Float32", {"data": 1e39}),  # out of float32 range
        ("std_msgs/msg/Float32", {"data": None}),  # null is NaN (D10)
        ("std_msgs/msg/Int8", {"data": 128}),
        ("std_msgs/msg/Int8", {"data": True}),  # a bool is not an int
        ("std_msgs/msg/Bool", {"data": 1}),
        ("std_msgs/msg/Header", {"stamp": "now", "frame_id": ""}),  # needs the clock
        ("std_msgs/msg/Header", {"stamp": {"secs": 1, "nsecs": 2}, "frame_id": ""}),
        ("std_msgs/msg/Header", {"stamp": {"sec": -1, "nanosec": 2**32}, "frame_id": ""}),
        ("std_msgs/msg/UInt8MultiArray", {"layout": {"dim": [], "data_offset": 0}, "data": [256]}),
        ("geometry_msgs/msg/Polygon", {"points": [{"x": 1.0, "y": 2.0}]}),  # inner default
    ],
)
def test_anything_else_takes_the_general_path(ros2: TypeRegistry, name: str, value: object) -> None:
    assert ros2.message(name).fast(value) is None


def test_results_do_not_alias_the_input(ros2: TypeRegistry) -> None:
    value = {"linear": {"x": 1.0, "y": 2.0, "z": 3.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
    fast = ros2.message("geometry_msgs/msg/Twist").fast(value)
    assert fast is not None
    value["linear"]["x"] = math.pi  # type: ignore[index]
    assert fast["linear"] == {"x": 1.0, "y": 2.0, "z": 3.0}


def test_ros1_times_use_the_ros1_keys(ros1: TypeRegistry) -> None:
    header = ros1.message("std_msgs/Header")
    value = {"seq": 3, "stamp": {"secs": 4, "nsecs": 5}, "frame_id": "base"}
    assert header.fast(value) == value
    assert header.fast({"seq": 3, "stamp": {"sec": 4, "nanosec": 5}, "frame_id": "b"}) is None


@pytest.mark.parametrize("dialect", [Dialect.ROS2, Dialect.ROS1])
def test_switched_off_every_type_takes_the_general_path_alike(dialect: Dialect) -> None:
    without = _registry(dialect, "generated-converters")
    with_fast = _registry(dialect, None)
    for name in without.message_names():
        mtype = without.message(name)
        assert mtype.fast is _no_fast and mtype.fast_converter() is None, name
        value = msgspec.json.decode(msgspec.json.encode(mtype.default(now=NOW)))
        assert mtype.from_json(value, now=NOW) == with_fast.message(name).from_json(value, now=NOW)
