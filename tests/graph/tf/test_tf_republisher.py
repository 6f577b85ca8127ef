"""Which transforms a republisher client gets at each tick: thresholds and requests."""

from __future__ import annotations

import math

import msgspec
import pytest
from tests.tf_support import transform

from rwt_graph.tf import TFBuffer, TFError, TFRequest, TFSubscription
from rwt_graph.types import Dialect, TypeRegistry

ANGLE = 0.1  # rad
DISTANCE = 0.05  # m


def request(sources: list[str], target: str = "base", **fields: float) -> TFRequest:
    values = {"angular_thres": ANGLE, "trans_thres": DISTANCE, "rate": 10.0, **fields}
    return TFRequest.from_message({"source_frames": sources, "target_frame": target, **values})


def move(buffer: TFBuffer, child: str, x: float = 0.0, yaw: float = 0.0) -> None:
    buffer.set_transform(transform("base", child, (x, 0.0, 0.0), yaw=yaw), static=False)


def sent(subscription: TFSubscription) -> dict[str, float]:
    """child frame -> x of what this tick sends."""
    return {
        t["child_frame_id"]: t["transform"]["translation"]["x"]  # type: ignore[index]
        for t in subscription.changed()
    }


@pytest.fixture
def buffer() -> TFBuffer:
    buffer = TFBuffer()
    move(buffer, "arm")
    move(buffer, "head")
    return buffer


def test_the_first_value_of_every_pair_is_sent_then_only_changes(buffer: TFBuffer) -> None:
    subscription = TFSubscription(buffer, request(["arm", "head"]), Dialect.ROS2)
    assert sent(subscription) == {"arm": 0.0, "head": 0.0}
    assert sent(subscription) == {}
    move(buffer, "arm", x=0.2)
    assert sent(subscription) == {"arm": 0.2}


def test_moves_within_the_thresholds_are_not_sent(buffer: TFBuffer) -> None:
    subscription = TFSubscription(buffer, request(["arm"]), Dialect.ROS2)
    sent(subscription)
    move(buffer, "arm", x=0.04, yaw=0.09)
    assert sent(subscription) == {}


def test_thresholds_compare_with_the_value_last_sent(buffer: TFBuffer) -> None:
    subscription = TFSubscription(buffer, request(["arm"]), Dialect.ROS2)
    sent(subscription)
    xs = [0.03, 0.06, 0.09, 0.12, 0.15]
    got = []
    for x in xs:  # 3 cm steps: each alone is under 5 cm, two together are not
        move(buffer, "arm", x=x)
        got.append(sent(subscription))
    assert got == [{}, {"arm": 0.06}, {}, {"arm": 0.12}, {}]


def test_a_rotation_beyond_angular_thres_is_sent(buffer: TFBuffer) -> None:
    subscription = TFSubscription(buffer, request(["arm"]), Dialect.ROS2)
    sent(subscription)
    move(buffer, "arm", yaw=0.11)
    [only] = subscription.changed()
    rotation = only["transform"]["rotation"]  # type: ignore[index]
    assert 2 * math.atan2(rotation["z"], rotation["w"]) == pytest.approx(0.11)


@pytest.mark.parametrize("zero", ["trans_thres", "angular_thres"])
def test_a_zero_threshold_sends_every_tick(buffer: TFBuffer, zero: str) -> None:
    subscription = TFSubscription(buffer, request(["arm"], **{zero: 0.0}), Dialect.ROS2)
    assert [sent(subscription) for _ in range(3)] == [{"arm": 0.0}] * 3


def test_pairs_that_cannot_be_looked_up_wait_until_they_can(buffer: TFBuffer) -> None:
    subscription = TFSubscription(buffer, request(["arm", "gripper"]), Dialect.ROS2)
    assert sent(subscription) == {"arm": 0.0}
    buffer.set_transform(transform("arm", "gripper", (0.5, 0.0, 0.0)), static=True)
    assert sent(subscription) == {"gripper": 0.5}


def test_goals_asking_the_same_share_each_lookup_and_message_at_a_tick(
    buffer: TFBuffer, monkeypatch: pytest.MonkeyPatch
) -> None:
    computed: list[tuple[str, str]] = []
    compute = buffer._lookup
    monkeypatch.setattr(buffer, "_lookup", lambda *pair: computed.append(pair) or compute(*pair))
    goals = [TFSubscription(buffer, request(["arm", "head"]), Dialect.ROS2) for _ in range(9)]
    goals.append(TFSubscription(buffer, request(["head"], trans_thres=0.0), Dialect.ROS2))
    ticks = [[goal.changed() for goal in goals] for _ in range(2)]
    assert sorted(computed) == [("base", "arm"), ("base", "head")]  # once for ten goals, two ticks
    first = ticks[0]
    assert all(sent[0] is first[0][0] and sent[1] is first[0][1] for sent in first[:9])
    assert first[9][0] is first[0][1]  # the same head transform, built once
    assert ticks[1][:9] == [[]] * 9 and len(ticks[1][9]) == 1  # a zero threshold: every tick

    move(buffer, "arm", x=0.2)  # a new transform: the next tick looks up again
    moved = [goal.changed() for goal in goals]
    assert sorted(computed[2:]) == [("base", "arm"), ("base", "head")]
    assert [len(sent) for sent in moved] == [1] * 10
    assert all(sent[0]["transform"]["translation"]["x"] == 0.2 for sent in moved[:9])  # type: ignore[index]


@pytest.mark.parametrize(
    ("dialect", "header"),
    [
        (Dialect.ROS2, {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": "base"}),
        (Dialect.ROS1, {"seq": 0, "stamp": {"secs": 1, "nsecs": 0}, "frame_id": "base"}),
    ],
)
def test_sent_transforms_are_stamped_transforms_of_the_dialect(
    buffer: TFBuffer, dialect: Dialect, header: dict[str, object]
) -> None:
    subscription = TFSubscription(buffer, request(["/arm"], target="/base"), dialect)
    assert subscription.changed() == [
        {
            "header": header,
            "child_frame_id": "arm",
            "transform": {
                "translation": {"x": 0.0, "y": 0.0, "z": 0.0},
                "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            },
        }
    ]


@pytest.mark.parametrize(
    ("dialect", "feedback_type", "array_type"),
    [
        (
            Dialect.ROS2,
            "tf2_web_republisher_interfaces/action/TFSubscription",
            "tf2_web_republisher_interfaces/msg/TFArray",
        ),
        (Dialect.ROS1, "tf2_web_republisher/TFSubscription", "tf2_web_republisher/TFArray"),
    ],
)
def test_sent_transforms_are_already_what_checking_them_would_give(
    dialect: Dialect, feedback_type: str, array_type: str
) -> None:
    """They go out unchecked (``validated=True``): checking them must change nothing."""
    buffer = TFBuffer()
    buffer.set_transform(
        transform("base", "arm", (1.0, -2.0, 0.25), yaw=-2.5, at=7.123), static=False
    )
    buffer.set_transform(transform("arm", "hand", (0.0, 0.5, 0.0), yaw=0.3), static=True)
    subscription = TFSubscription(buffer, request(["arm", "hand"]), dialect)
    sent = {"transforms": subscription.changed()}
    registry = TypeRegistry(dialect=dialect)
    for msgtype in (registry.action(feedback_type).feedback, registry.message(array_type)):
        checked = msgtype.from_json(sent, now=0.0)
        assert checked.missing == ()
        assert checked.msg == sent
        assert msgspec.json.encode(checked.msg) == msgspec.json.encode(sent)  # same key order


def test_names_are_sent_as_the_request_spells_them_after_one_slash_goes() -> None:
    buffer = TFBuffer()
    buffer.set_transform(transform("base", "arm", (1.0, 0.0, 0.0)), static=False)
    plain = TFSubscription(buffer, request(["/arm"], target="/base"), Dialect.ROS2)
    doubled = TFSubscription(buffer, request(["//arm"], target="//base"), Dialect.ROS2)
    [sent] = plain.changed()
    [respelled] = doubled.changed()  # looked up as arm in base, named /arm in /base
    assert (sent["child_frame_id"], sent["header"]["frame_id"]) == ("arm", "base")  # type: ignore[index]
    assert respelled["child_frame_id"] == "/arm"
    assert respelled["header"]["frame_id"] == "/base"  # type: ignore[index]
    assert respelled["transform"] == sent["transform"]
    assert sent["header"]["frame_id"] == "base"  # type: ignore[index]  # the shared one intact


def test_requests_are_normalised_and_bounded() -> None:
    asked = request(["/arm", "arm", "", "head"], target="/base", rate=0.0)
    assert asked.source_frames == ("arm", "head") and asked.target_frame == "base"
    assert asked.period_s == pytest.approx(0.1)  # no rate: 10 Hz
    assert request([], rate=1000.0).period_s == pytest.approx(0.01)  # at most 100 Hz
    assert request([], rate=2.0).period_s == pytest.approx(0.5)
    with pytest.raises(TFError, match="target_frame is empty"):
        request(["arm"], target="")
    with pytest.raises(TFError, match="at most 1000 source frames"):
        request([f"f{i}" for i in range(1001)])
