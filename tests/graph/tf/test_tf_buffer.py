"""TF buffer lookups: chains, inverses, static and dynamic links, time, errors, bounds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tests.tf_support import tf_message, transform, yaw_of

from rwt_graph.tf import (
    DisconnectedFramesError,
    ExtrapolationError,
    TFBuffer,
    TFError,
    UnknownFrameError,
)
from rwt_graph.tf.transform import quaternion

QUARTER = math.pi / 2


def position(buffer: TFBuffer, target: str, source: str) -> list[float]:
    return [round(float(v), 9) for v in buffer.lookup(target, source).matrix[:3, 3]]


def yaw(buffer: TFBuffer, target: str, source: str) -> float:
    msg = buffer.lookup(target, source).transform
    return yaw_of(msg["rotation"])  # type: ignore[arg-type]


@pytest.fixture
def robot() -> TFBuffer:
    """map -> odom -> base_link -> {arm, camera}; base_link turned a quarter left."""
    buffer = TFBuffer()
    buffer.add_message(
        tf_message(
            transform("map", "odom", (1.0, 0.0, 0.0)),
            transform("odom", "base_link", (2.0, 0.0, 0.0), yaw=QUARTER),
            transform("base_link", "arm", (1.0, 0.0, 0.0)),
        ),
        static=False,
    )
    buffer.add_message(
        tf_message(transform("base_link", "camera", (0.0, 0.0, 1.0), at=0.0)), static=True
    )
    return buffer


def test_a_chain_composes_translations_and_rotations(robot: TFBuffer) -> None:
    # arm is 1 m ahead of base_link, which faces +y in odom, 3 m from map's origin
    assert position(robot, "map", "arm") == [3.0, 1.0, 0.0]
    assert yaw(robot, "map", "arm") == pytest.approx(QUARTER)


def test_the_inverse_lookup_undoes_the_forward_one(robot: TFBuffer) -> None:
    forward = robot.lookup("map", "arm").matrix
    backward = robot.lookup("arm", "map").matrix
    np.testing.assert_allclose(forward @ backward, np.eye(4), atol=1e-12)
    assert position(robot, "arm", "map") == [-1.0, 3.0, 0.0]


def test_siblings_meet_at_their_common_parent(robot: TFBuffer) -> None:
    assert position(robot, "arm", "camera") == [-1.0, 0.0, 1.0]
    assert position(robot, "base_link", "base_link") == [0.0, 0.0, 0.0]


def test_static_links_take_no_part_in_the_common_time(robot: TFBuffer) -> None:
    robot.add_message(
        tf_message(transform("odom", "base_link", (5.0, 0.0, 0.0), at=2.0)), static=False
    )
    result = robot.lookup("odom", "camera")
    assert result.stamp == pytest.approx(2.0)
    assert position(robot, "odom", "camera") == [5.0, 0.0, 1.0]
    assert robot.lookup("base_link", "camera").stamp == 0.0  # static only


def test_lookups_use_the_latest_common_time_and_interpolate() -> None:
    buffer = TFBuffer()
    buffer.add_message(
        tf_message(
            transform("odom", "base_link", (0.0, 0.0, 0.0), at=1.0),
            transform("odom", "base_link", (1.0, 0.0, 0.0), yaw=QUARTER, at=2.0),
            transform("base_link", "arm", (0.0, 0.0, 0.0), at=1.5),
        ),
        static=False,
    )
    result = buffer.lookup("odom", "arm")
    assert result.stamp == pytest.approx(1.5)
    assert position(buffer, "odom", "arm") == [0.5, 0.0, 0.0]
    assert yaw(buffer, "odom", "arm") == pytest.approx(QUARTER / 2)
    # base_link alone is at its own latest sample
    assert position(buffer, "odom", "base_link") == [1.0, 0.0, 0.0]


def test_out_of_order_samples_are_kept_in_time_order() -> None:
    buffer = TFBuffer()
    for at, x in ((3.0, 3.0), (1.0, 1.0), (2.0, 2.0)):
        buffer.set_transform(transform("a", "b", (x, 0.0, 0.0), at=at), static=False)
    buffer.set_transform(transform("b", "c", at=2.5), static=False)
    assert position(buffer, "a", "c") == [2.5, 0.0, 0.0]


def test_a_link_without_the_common_time_cannot_be_extrapolated() -> None:
    buffer = TFBuffer()
    buffer.set_transform(transform("odom", "base_link", at=5.0), static=False)
    buffer.set_transform(transform("base_link", "arm", at=1.0), static=False)
    with pytest.raises(ExtrapolationError, match="base_link -> odom"):
        buffer.lookup("odom", "arm")


def test_unknown_and_disconnected_frames_are_named(robot: TFBuffer) -> None:
    with pytest.raises(UnknownFrameError, match="'gripper'"):
        robot.lookup("map", "gripper")
    robot.set_transform(transform("world", "satellite"), static=False)
    with pytest.raises(DisconnectedFramesError, match="roots 'world' and 'map'"):
        robot.lookup("satellite", "arm")


def test_a_leading_slash_is_ignored(robot: TFBuffer) -> None:
    robot.set_transform(transform("/arm", "/gripper", (0.5, 0.0, 0.0)), static=False)
    assert robot.has_frame("gripper") and robot.has_frame("/gripper")
    assert robot.parent("/gripper") == "arm"
    assert position(robot, "/map", "gripper") == [3.0, 1.5, 0.0]
    assert "gripper" in robot.frames() and "/gripper" not in robot.frames()


def test_a_loop_of_frames_is_an_error_not_a_hang() -> None:
    buffer = TFBuffer()
    buffer.set_transform(transform("a", "b"), static=False)
    buffer.set_transform(transform("b", "a"), static=False)
    buffer.set_transform(transform("b", "c"), static=False)
    with pytest.raises(TFError, match="loop"):
        buffer.lookup("c", "a")


def test_bad_transforms_are_refused_and_the_rest_of_the_message_kept() -> None:
    buffer = TFBuffer()
    broken = transform("a", "b")
    broken["transform"]["translation"]["x"] = math.nan  # type: ignore[index]
    stored = buffer.add_message(
        tf_message(transform("", "x"), transform("y", "y"), broken, transform("a", "c")),
        static=False,
    )
    assert stored == 1
    assert buffer.frames() == ["a", "c"]


def test_a_new_parent_replaces_the_link() -> None:
    buffer = TFBuffer()
    buffer.set_transform(transform("odom", "base_link", (1.0, 0.0, 0.0)), static=False)
    buffer.set_transform(transform("map", "base_link", (2.0, 0.0, 0.0)), static=False)
    assert buffer.parent("base_link") == "map"
    assert buffer.frames() == ["base_link", "map"]  # odom is named by no link any more
    assert position(buffer, "map", "base_link") == [2.0, 0.0, 0.0]


def test_history_is_bounded_by_time_count_and_frames() -> None:
    buffer = TFBuffer(cache_time_s=2.0, max_samples=5, max_frames=4)
    for step in range(10):
        buffer.set_transform(transform("a", "b", (step, 0.0, 0.0), at=float(step)), static=False)
    buffer.set_transform(transform("b", "c", at=6.5), static=False)
    with pytest.raises(ExtrapolationError):  # 6.5 is older than the 2 s kept behind 9
        buffer.lookup("a", "c")
    for step in range(10):
        buffer.set_transform(transform("a", "d", at=100 + step * 1e-3), static=False)
    buffer.set_transform(transform("d", "e", at=100.0), static=False)
    with pytest.raises(ExtrapolationError):  # only the last 5 samples of a -> d remain
        buffer.lookup("a", "e")
    with pytest.raises(TFError, match="more than 4 frames"):  # b, c, d and e are held
        buffer.set_transform(transform("a", "f"), static=False)
    buffer.set_transform(transform("a", "b", at=20.0), static=False)  # known frames still update


def test_a_zero_quaternion_counts_as_no_rotation() -> None:
    buffer = TFBuffer()
    msg = transform("a", "b", (1.0, 0.0, 0.0))
    msg["transform"]["rotation"] = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 0.0}  # type: ignore[index]
    buffer.set_transform(msg, static=True)
    np.testing.assert_allclose(quaternion(buffer.lookup("a", "b").matrix), [0, 0, 0, 1])


def counting_lookups(buffer: TFBuffer, monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, str]]:
    """Record every lookup the buffer actually computes (rather than remembers)."""
    computed: list[tuple[str, str]] = []
    compute = buffer._lookup

    def counted(target: str, source: str) -> object:
        computed.append((target, source))
        return compute(target, source)

    monkeypatch.setattr(buffer, "_lookup", counted)
    return computed


def test_a_lookup_is_computed_once_until_a_transform_arrives(
    robot: TFBuffer, monkeypatch: pytest.MonkeyPatch
) -> None:
    computed = counting_lookups(robot, monkeypatch)
    first = robot.lookup("map", "arm")
    assert robot.lookup("/map", "arm") is first
    assert robot.lookup_each("map", ("arm", "camera"))[0] is first
    assert computed == [("map", "arm"), ("map", "camera")]
    # the same values again, at a later stamp: a new tree version, computed again
    robot.set_transform(transform("base_link", "arm", (1.0, 0.0, 0.0), at=2.0), static=False)
    again = robot.lookup("map", "arm")
    assert again is not first and computed[-1] == ("map", "arm")
    assert again.stamp == 1.0  # still the latest common time: map -> odom holds 1 s
    assert again.matrix.tobytes() == first.matrix.tobytes()


def test_errors_are_computed_once_but_raised_afresh(
    robot: TFBuffer, monkeypatch: pytest.MonkeyPatch
) -> None:
    computed = counting_lookups(robot, monkeypatch)
    raised = []
    for _ in range(3):
        with pytest.raises(UnknownFrameError, match="'nowhere' does not exist") as info:
            robot.lookup("map", "nowhere")
        raised.append(info.value)
    assert len(computed) == 1
    assert raised[0] is not raised[1] is not raised[2]
    [error] = robot.lookup_each("map", ("nowhere",))
    assert isinstance(error, UnknownFrameError) and len(computed) == 1


def test_results_are_read_only() -> None:
    buffer = TFBuffer()
    buffer.set_transform(transform("a", "b", (1.0, 0.0, 0.0)), static=False)
    for found in (buffer.lookup("a", "b"), buffer.lookup("b", "a"), buffer.lookup("a", "a")):
        with pytest.raises(ValueError, match="read-only"):
            found.matrix[0, 3] = 5.0


def chain_message(step: int) -> dict[str, object]:
    """a -> b -> c -> d -> e, each turned and shifted; ``step`` moves one link in three."""
    links = [("a", "b"), ("b", "c"), ("c", "d"), ("d", "e")]
    moved = step % 3  # the leaf side, the middle, the top in turn
    transforms = [
        transform(parent, child, (0.1 * i + 0.3, -0.2, 0.05 * i), yaw=0.4 * i - 0.7, at=step + 1)
        for i, (parent, child) in enumerate(links)
    ]
    position = transforms[3 - moved]["transform"]["translation"]  # type: ignore[index]
    position["x"] += 0.01 * step  # type: ignore[index]
    transforms[1 + (moved == 1)]["transform"]["rotation"] = (  # type: ignore[index]
        transform("", "", yaw=0.013 * step)["transform"]["rotation"]  # type: ignore[index]
    )
    return tf_message(*transforms)


def test_reused_products_give_bit_for_bit_what_a_fresh_buffer_gives() -> None:
    buffer = TFBuffer()
    pairs = [("a", "e"), ("e", "a"), ("b", "e"), ("c", "a"), ("e", "c")]
    for step in range(7):
        msg = chain_message(step)
        buffer.add_message(msg, static=False)
        fresh = TFBuffer()
        fresh.add_message(msg, static=False)
        for target, source in pairs:
            kept, new = buffer.lookup(target, source), fresh.lookup(target, source)
            assert kept.matrix.tobytes() == new.matrix.tobytes(), (step, target, source)
            assert (kept.translation, kept.rotation) == (new.translation, new.rotation)
            assert kept.stamp == new.stamp == step + 1


def test_routes_follow_a_new_parent_and_a_frame_turning_static(robot: TFBuffer) -> None:
    assert position(robot, "map", "arm") == [3.0, 1.0, 0.0]
    robot.set_transform(transform("odom", "arm", (0.0, 5.0, 0.0)), static=False)
    assert position(robot, "map", "arm") == [1.0, 5.0, 0.0]
    robot.set_transform(transform("odom", "arm", (0.0, 6.0, 0.0), at=0.0), static=True)
    assert position(robot, "map", "arm") == [1.0, 6.0, 0.0]
    assert robot.lookup("arm", "odom").stamp == 0.0  # only a static link between them
