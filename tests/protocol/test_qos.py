"""Protocol 2.1.0's ``qos`` object: read as the reference reads it, refused with the field named."""

from __future__ import annotations

import math

import pytest

from rwt_protocol.codecs.json import parse_object
from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.ops import Advertise, Publish, Subscribe
from rwt_protocol.qos import (
    DEFAULT_DEPTH,
    MAX_DEPTH,
    Durability,
    History,
    QosProfile,
    Reliability,
    incompatibilities,
)

FULL = {
    "history": "keep_last",
    "depth": 10,
    "reliability": "reliable",
    "durability": "volatile",
    "deadline": "infinite",
    "lifespan": 1.5,
}


def _qos(op: str, qos: object) -> QosProfile:
    frame = {"op": op, "topic": "/t", "type": "std_msgs/msg/String", "qos": qos}
    parsed = parse_object(frame)
    assert isinstance(parsed, Advertise | Publish | Subscribe)
    assert parsed.qos is not None
    return parsed.qos.profile()


@pytest.mark.parametrize("op", ["advertise", "publish", "subscribe"])
def test_the_specs_full_example_is_read_on_every_op(op: str) -> None:
    profile = _qos(op, FULL)
    assert profile == QosProfile(depth=10, lifespan_s=1.5)
    assert profile.to_json() == {**FULL, "lifespan": 1.5}


def test_an_empty_object_is_the_system_default_and_absent_is_none() -> None:
    assert _qos("advertise", {}) == QosProfile()
    assert QosProfile().describe() == f"keep_last {DEFAULT_DEPTH}, reliable, volatile"
    advertise = parse_object({"op": "advertise", "topic": "/t", "type": "std_msgs/String"})
    assert isinstance(advertise, Advertise) and advertise.qos is None


def test_durations_in_each_spelling() -> None:
    assert _qos("subscribe", {"lifespan": {"secs": 1, "nsecs": 500_000_000}}).lifespan_s == 1.5
    assert _qos("subscribe", {"lifespan": 2}).lifespan_s == 2.0
    assert _qos("subscribe", {"lifespan": "INFINITE"}).lifespan_s == math.inf
    assert _qos("subscribe", {"lifespan": 0}).lifespan_s == math.inf  # unspecified
    assert _qos("subscribe", {"deadline": 1e300}).deadline_s == math.inf
    profile = _qos("subscribe", {"deadline": "best_available"})
    assert profile.deadline_best_available and profile.deadline_s == math.inf


def test_policy_names_in_any_case_and_unknown_fields_ignored() -> None:
    profile = _qos("advertise", {"reliability": "BEST_EFFORT", "Durability": "x", "liveliness": 3})
    assert profile.reliability is Reliability.BEST_EFFORT
    assert profile.durability is Durability.VOLATILE


@pytest.mark.parametrize(
    ("qos", "text"),
    [
        ("abcd", "expected object, got str at $.qos"),
        (42, "expected object, got int at $.qos"),
        (["depth", 10], "expected object, got array at $.qos"),
        ({"reliability": "fast"}, "got 'fast' at $.qos.reliability"),
        ({"durability": "sticky"}, "got 'sticky' at $.qos.durability"),
        ({"history": "last_one"}, "got 'last_one' at $.qos.history"),
        ({"depth": -1}, "expected a number >= 0, got -1 at $.qos.depth"),
        ({"depth": 1.5}, "expected int, got float at $.qos.depth"),
        ({"depth": "ten"}, "expected int, got str at $.qos.depth"),
        ({"depth": True}, "expected int, got bool at $.qos.depth"),
        ({"depth": 2**64}, "at $.qos.depth"),
        ({"deadline": "soon"}, "or 'best_available', got 'soon' at $.qos.deadline"),
        ({"lifespan": "best_available"}, "expected 'infinite', got 'best_available' at $.qos."),
        ({"deadline": [1, 0]}, "got array at $.qos.deadline"),
        ({"lifespan": False}, "got bool at $.qos.lifespan"),
        ({"lifespan": -0.5}, "expected a duration >= 0 seconds, got -0.5 at $.qos.lifespan"),
        ({"lifespan": {"secs": 1}}, "expected secs and nsecs as integers >= 0"),
        ({"lifespan": {"secs": -1, "nsecs": 0}}, "at $.qos.lifespan"),
        ({"lifespan": {"secs": 1.5, "nsecs": 0}}, "at $.qos.lifespan"),
    ],
)
def test_a_bad_qos_refuses_the_op_naming_the_field(qos: object, text: str) -> None:
    # the reference's invalid profiles (rosbridge_library test_qos.py) and a few more
    for op in ("advertise", "publish", "subscribe"):
        with pytest.raises(RemoteProtocolError) as caught:
            _qos(op, qos)
        assert str(caught.value).startswith(f"{op}: ")
        assert text in str(caught.value)


def test_keep_all_and_a_hostile_depth_are_capped() -> None:
    assert _qos("subscribe", {"history": "keep_all"}).keep == MAX_DEPTH
    huge = _qos("subscribe", {"depth": 10**9})
    assert huge.depth == 10**9 and huge.keep == MAX_DEPTH and huge.capped
    assert _qos("subscribe", {"depth": 0}).keep == DEFAULT_DEPTH  # the system default depth
    assert _qos("subscribe", {"history": "keep_all"}).history is History.KEEP_ALL


def test_best_available_resolves_as_rmw_does() -> None:
    asked = QosProfile(
        reliability=Reliability.BEST_AVAILABLE,
        durability=Durability.BEST_AVAILABLE,
        deadline_best_available=True,
        deadline_s=math.inf,
    )
    offer = QosProfile(reliability=Reliability.BEST_EFFORT, deadline_s=0.5)
    resolved = asked.for_subscription(offer)
    assert resolved.reliability is Reliability.BEST_EFFORT
    assert resolved.durability is Durability.VOLATILE
    assert resolved.deadline_s == 0.5 and not resolved.deadline_best_available
    assert not incompatibilities(offer, resolved)
    publisher = asked.for_publisher()
    assert publisher.reliability is Reliability.RELIABLE and publisher.transient_local


def test_incompatible_pairs_follow_ros2s_request_versus_offer_rules() -> None:
    best_effort = QosProfile(reliability=Reliability.BEST_EFFORT)
    durable = QosProfile(durability=Durability.TRANSIENT_LOCAL)
    assert incompatibilities(best_effort, QosProfile()) == [
        "reliability: reliable asked of a best_effort publisher"
    ]
    assert incompatibilities(QosProfile(), durable) == [
        "durability: transient_local asked of a volatile publisher"
    ]
    assert incompatibilities(QosProfile(deadline_s=5), QosProfile(deadline_s=4)) == [
        "deadline: 4 s asked of a publisher offering 5 s"
    ]
    assert not incompatibilities(durable, QosProfile(reliability=Reliability.BEST_EFFORT))
    assert not incompatibilities(QosProfile(deadline_s=1), QosProfile(deadline_s=2))
