"""Bounded field paths used on their own: a partial message is read, never a crash.

``compile_field``, ``BoundedField.values``, ``non_finite`` and ``replaced`` are what
the envelope applies to each command (docs/safety.md). The envelope gives them whole
messages (converted to the topic's type); given a partial or odd one they skip what
is absent, as their docstrings say, and ``replaced`` refuses a container it cannot copy.
"""

from __future__ import annotations

import pytest

from rwt import Graph
from rwt_graph.safety.fields import compile_field, non_finite, replaced

REGISTRY = Graph().registry
JOINTS = REGISTRY.message("sensor_msgs/msg/JointState")
CLOUD = REGISTRY.message("sensor_msgs/msg/ChannelFloat32")
TWIST = REGISTRY.message("geometry_msgs/msg/Twist")


def test_absent_and_odd_values_are_skipped() -> None:
    every = compile_field(JOINTS, "velocity[*]", -2, 2, REGISTRY.message)
    assert list(every.values({"velocity": [3.0, 1.0]})) == [
        (("velocity", 0), 3.0),
        (("velocity", 1), 1.0),
    ]
    assert list(every.values({})) == []  # no such field in the message
    assert list(every.values({"velocity": 3.0})) == []  # not an array
    assert list(every.values([3.0])) == []  # not a message
    nested = compile_field(TWIST, "linear.x", -1, 1, REGISTRY.message)
    assert list(nested.values({"linear": None, "angular": {"x": 9.0}})) == []
    assert list(nested.values({"linear": [9.0]})) == []


def test_non_finite_reads_a_partial_message() -> None:
    plans: dict[str, tuple[tuple[str, bool, object], ...]] = {}
    lookup = REGISTRY.message
    assert non_finite(TWIST, {"angular": {"z": float("inf")}}, lookup, plans) == (
        "angular.z",
        float("inf"),
    )  # type: ignore[arg-type]
    assert non_finite(TWIST, {"linear": "fast"}, lookup, plans) is None  # type: ignore[arg-type]
    assert non_finite(CLOUD, {"values": ["a", "b"]}, lookup, plans) is None  # type: ignore[arg-type]
    assert non_finite(CLOUD, {"values": 1.5}, lookup, plans) is None  # type: ignore[arg-type]
    assert non_finite(CLOUD, {"values": (1.0, float("nan"))}, lookup, plans) == (
        "values[1]",
        pytest.approx(float("nan"), nan_ok=True),
    )  # type: ignore[arg-type]


def test_replaced_copies_only_what_it_changes_and_refuses_what_it_cannot_copy() -> None:
    msg: dict[str, object] = {"linear": {"x": 2.0, "y": 3.0}, "angular": {"z": 0.0}}
    out = replaced(msg, [(("linear", "x"), 1.0), (("linear", "y"), 1.0)])
    assert out == {"linear": {"x": 1.0, "y": 1.0}, "angular": {"z": 0.0}}
    assert msg["linear"] == {"x": 2.0, "y": 3.0} and out["angular"] is msg["angular"]
    with pytest.raises(TypeError, match="cannot copy a range"):
        replaced({"values": range(3)}, [(("values", 0), 0.0)])
