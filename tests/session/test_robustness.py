"""Bad input never breaks a session (D1; REF §1.4 names what breaks the reference).

Every case: the sender gets error status frames only (never an internal error,
never an exception), keeps being served, and another connection on the same
graph does not notice.
"""

from __future__ import annotations

import json

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from rwt_graph.graph import Graph
from tests.conftest import FakeClock, Peer


def still_served(sender: Peer, other: Peer) -> None:
    """The sender can still publish and the other connection still receives it."""
    sender.send(op="publish", topic="/probe", msg={"data": "alive"})
    assert other.received() == [{"op": "publish", "topic": "/probe", "msg": {"data": "alive"}}]


def pair(graph: Graph) -> tuple[Peer, Peer]:
    sender, other = Peer(graph, "sender"), Peer(graph, "other")
    sender.send(op="advertise", topic="/probe", type="std_msgs/String")
    other.send(op="subscribe", topic="/probe")
    return sender, other


def only_error_statuses(frames: list[dict[str, object]]) -> None:
    assert frames, "a bad frame must get a status (D1)"
    for frame in frames:
        assert frame["op"] == "status" and frame["level"] == "error", frame
        assert "internal error" not in str(frame["msg"])


# REF §1.4: each of these kills the reference's per-client worker thread.
REFERENCE_BREAKERS = {
    "top-level-number": b"5",
    "top-level-true": b"true",
    "top-level-null": b"null",
    "top-level-string-containing-id": b'"valid"',
    "top-level-string-containing-op": b'"stop"',
    "top-level-array-with-id": b'["id"]',
    "top-level-array-with-op": b'["op", 1]',
    "unhashable-op-list": b'{"op":["publish"],"topic":"/probe"}',
    "unhashable-op-object": b'{"op":{"a":1},"topic":"/probe"}',
    "fragment-size-zero": b'{"op":"subscribe","topic":"/probe","fragment_size":0}',
    "fragment-size-negative": b'{"op":"subscribe","topic":"/probe","fragment_size":-5}',
    "fragment-size-not-a-number": b'{"op":"subscribe","topic":"/probe","fragment_size":"big"}',
    "fragment-size-null-on-call": b'{"op":"call_service","service":"/x","fragment_size":"1"}',
    "no-op": b'{"receiver":"/rosbridge","msg":{}}',
    "unknown-op": b'{"op":"service_request"}',
    "invalid-json": b'{"op":"publish",',
    "not-utf8": b"\xff\xfe{",
}


@pytest.mark.parametrize("frame", REFERENCE_BREAKERS.values(), ids=REFERENCE_BREAKERS.keys())
def test_reference_breakers_get_a_status_and_change_nothing(graph: Graph, frame: bytes) -> None:
    sender, other = pair(graph)
    sender.send_raw(frame)
    frames = [f for f in sender.received() if f["op"] != "service_response"]  # D4 replies
    only_error_statuses(frames)
    still_served(sender, other)


def test_a_png_key_without_msg_is_an_ignored_extra_field(graph: Graph) -> None:
    # REF §1.4: the reference reads msg["msg"] for any op with a "png" key and dies.
    sender, other = pair(graph)
    sender.send_raw(b'{"op":"set_level","level":"info","png":"x"}')
    assert sender.statuses() == [
        {"op": "status", "level": "info", "msg": "set_level: status level is info"}
    ]
    sender.send_raw(b'{"op":"subscribe","topic":"/probe","png":"on"}')
    sender.received()
    other.send(op="advertise", topic="/probe", type="std_msgs/String")
    other.send(op="publish", topic="/probe", msg={"data": "plain"})
    assert sender.received() == [{"op": "publish", "topic": "/probe", "msg": {"data": "plain"}}]


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=10),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=10,
)
op_names = st.sampled_from(
    [
        "advertise",
        "unadvertise",
        "publish",
        "subscribe",
        "unsubscribe",
        "call_service",
        "advertise_service",
        "unadvertise_service",
        "service_response",
        "send_action_goal",
        "cancel_action_goal",
        "advertise_action",
        "unadvertise_action",
        "action_feedback",
        "action_result",
        "fragment",
        "png",
        "set_level",
        "status",
        "auth",
    ]
)
ops = st.builds(
    lambda name, fields: {**fields, "op": name},
    op_names,
    st.dictionaries(
        st.sampled_from(
            [
                *("topic", "type", "msg", "id", "service", "args", "values", "result", "action"),
                *("throttle_rate", "queue_length", "fragment_size", "compression", "level"),
                *("data", "num", "total", "latch", "timeout", "feedback", "action_type", "status"),
            ]
        ),
        json_values,
        max_size=6,
    ),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@example(frames=[b'"\x80"'])  # invalid UTF-8 in a JSON string
@given(frames=st.lists(st.binary(max_size=60) | json_values.map(json.dumps).map(str.encode)))
def test_arbitrary_bytes_and_json_values_only_ever_get_statuses(frames: list[bytes]) -> None:
    graph = Graph(clock=FakeClock())
    sender, other = pair(graph)
    for frame in frames:
        sender.send_raw(frame)
    for out in sender.received():
        assert out["op"] == "status" or out["op"] in ("service_response", "action_result")
        assert "internal error" not in json.dumps(out)
    still_served(sender, other)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@example(messages=[{"op": "png", "topic": None, "data": "\x80"}])  # non-ASCII base64
@given(messages=st.lists(ops, max_size=5))
def test_arbitrary_ops_never_raise_nor_hit_an_internal_error(
    messages: list[dict[str, object]],
) -> None:
    graph = Graph(clock=FakeClock())
    sender, other = pair(graph)
    for message in messages:
        sender.send_raw(json.dumps(message))
    assert all("internal error" not in json.dumps(f) for f in sender.received())
    other.received()
    sender.send(op="publish", topic="/probe", msg={"data": "alive"})
    assert {"op": "publish", "topic": "/probe", "msg": {"data": "alive"}} in other.received()
