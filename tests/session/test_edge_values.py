"""Values a client cannot make the server choke on: names, ids, integers, strings.

Edge rules (docs/limits.md): names follow ROS's naming rules, every string is
valid Unicode (no lone surrogate), every integer of an op fits in 64 bits;
a breach gets an error status naming the field. Whatever still cannot be
encoded on the way out becomes a failure reply or an error status, never an
exception, and a disconnect's cleanup always completes.
"""

from __future__ import annotations

import json
import logging
from typing import Any

import cbor2
import pytest

from rwt_graph.graph import Graph
from rwt_graph.rosapi import install_rosapi
from rwt_protocol import ops
from rwt_protocol.server import handlers
from tests.conftest import FakeClock, Peer
from tests.session.rosapi_support import call, connect
from tests.session.test_robustness import pair, still_served

TRIGGER = "std_srvs/srv/Trigger"
FIB = "example_interfaces/action/Fibonacci"
LONE = "\ud800"


def error_texts(peer: Peer) -> list[str]:
    frames = peer.received()
    assert all(f["op"] in ("status", "service_response", "action_result") for f in frames), frames
    statuses = [f for f in frames if f["op"] == "status"]
    assert statuses and all(f["level"] == "error" for f in statuses), frames
    return [str(f["msg"]) for f in statuses]


# One op per field a lone surrogate can hide in (json.dumps writes it as "\ud800").
SURROGATE_OPS: dict[str, dict[str, Any]] = {
    "subscribe-id": {"op": "subscribe", "topic": "/probe", "id": LONE},
    "subscribe-topic": {"op": "subscribe", "topic": f"/a{LONE}"},
    "advertise-topic": {"op": "advertise", "topic": LONE, "type": "std_msgs/String"},
    "advertise-type": {"op": "advertise", "topic": "/t", "type": f"std_msgs/{LONE}"},
    "publish-topic": {"op": "publish", "topic": f"/{LONE}", "msg": {"data": "x"}},
    "publish-string-field": {"op": "publish", "topic": "/probe", "msg": {"data": LONE}},
    "publish-object-key": {"op": "publish", "topic": "/probe", "msg": {LONE: 1}},
    "call_service-service": {"op": "call_service", "service": f"/s{LONE}", "id": "c"},
    "call_service-id": {"op": "call_service", "service": "/rosapi/topics", "id": LONE},
    "call_service-args": {
        "op": "call_service",
        "service": "/rosapi/set_param",
        "args": {"name": f"/robot:{LONE}", "value": "1"},
    },
    "advertise_service-service": {"op": "advertise_service", "service": LONE, "type": TRIGGER},
    "send_action_goal-action": {"op": "send_action_goal", "action": LONE, "action_type": FIB},
    "send_action_goal-id": {
        "op": "send_action_goal",
        "action": "/fib",
        "action_type": FIB,
        "id": LONE,
    },
    "status-msg": {"op": "status", "level": "error", "msg": LONE},
    "service_response-values": {
        "op": "service_response",
        "service": "/s",
        "id": "service_request:/s:1",
        "result": True,
        "values": {"message": LONE},
    },
    "service_response-failure-text": {
        "op": "service_response",
        "service": "/s",
        "id": "service_request:/s:1",
        "result": False,
        "values": LONE,
    },
    "action_feedback-values": {
        "op": "action_feedback",
        "action": "/fib",
        "id": "g",
        "values": {"partial_sequence": [], "note": LONE},
    },
    "action_result-values": {
        "op": "action_result",
        "action": "/fib",
        "id": "g",
        "result": False,
        "values": LONE,
    },
}


@pytest.mark.parametrize("op", SURROGATE_OPS.values(), ids=SURROGATE_OPS.keys())
def test_a_lone_surrogate_anywhere_gets_an_error_status(graph: Graph, op: dict[str, Any]) -> None:
    install_rosapi(graph)
    sender, other = pair(graph)
    sender.send(**op)  # receive_frame must not raise
    [text] = error_texts(sender)
    assert "lone surrogate" in text
    still_served(sender, other)
    assert all(LONE not in name for name in graph.topics)
    assert all(LONE not in name for name in graph.params.names())


@pytest.mark.parametrize(
    ("op", "field"),
    [
        ({"op": "subscribe", "topic": "a b"}, "$.topic"),
        ({"op": "advertise", "topic": "1abc", "type": "std_msgs/String"}, "$.topic"),
        ({"op": "publish", "topic": "/a/b-c", "msg": {}}, "$.topic"),
        ({"op": "unsubscribe", "topic": ""}, "$.topic"),
        ({"op": "call_service", "service": "/x y", "id": 1}, "$.service"),
        ({"op": "call_service", "service": "/x.y#7"}, "$.service"),
        ({"op": "advertise_service", "service": "/", "type": TRIGGER}, "$.service"),
        ({"op": "send_action_goal", "action": "/a.b", "action_type": FIB}, "$.action"),
        ({"op": "advertise_action", "action": "a//", "type": FIB}, None),  # valid: a// is a
        ({"op": "subscribe", "topic": "/" + "a" * 1025}, "$.topic"),
    ],
    ids=lambda v: str(v)[:40] if isinstance(v, dict) else str(v),
)
def test_names_follow_ros_naming_rules(graph: Graph, op: dict[str, Any], field: str | None) -> None:
    sender, other = pair(graph)
    sender.send(**op)
    if field is None:
        assert sender.statuses() == []
    else:
        [text] = error_texts(sender)
        assert text.startswith(f"{op['op']}: ") and text.endswith(f" at {field}")
        assert "name" in text
    still_served(sender, other)
    assert "/" + "a" * 1025 not in graph.topics


@pytest.mark.parametrize(
    "name", ["chatter", "/a/b", "~private", "//a//b/", "/rosapi/topics", "_hidden", "a1/b_2"]
)
def test_names_real_clients_use_are_accepted(graph: Graph, name: str) -> None:
    sender, other = pair(graph)
    sender.send(op="advertise", topic=name, type="std_msgs/String", id="ok")
    sender.send(op="subscribe", topic=name, id="ok2")
    assert sender.statuses() == []
    still_served(sender, other)


@pytest.mark.parametrize(
    ("op", "field"),
    [
        ({"op": "subscribe", "topic": "/probe", "id": 2**63}, "$.id"),
        ({"op": "subscribe", "topic": "/probe", "id": -(2**63) - 1}, "$.id"),
        ({"op": "subscribe", "topic": "/probe", "throttle_rate": 10**30}, "$.throttle_rate"),
        ({"op": "subscribe", "topic": "/probe", "queue_length": 2**64}, "$.queue_length"),
        ({"op": "subscribe", "topic": "/probe", "fragment_size": 2**64}, "$.fragment_size"),
        ({"op": "fragment", "id": "f", "data": "x", "num": 2**64, "total": 1}, "$.num"),
        ({"op": "fragment", "id": "f", "data": "x", "num": 0, "total": 2**64}, "$.total"),
        ({"op": "publish", "topic": "/probe", "msg": {"data": "x"}, "id": 2**64}, "$.id"),
        ({"op": "action_result", "action": "/f", "id": "g", "result": True, "status": 2**70}, None),
    ],
    ids=lambda v: str(v)[:50] if isinstance(v, dict) else str(v),
)
def test_integers_beyond_64_bits_are_refused(
    graph: Graph, op: dict[str, Any], field: str | None
) -> None:
    sender, other = pair(graph)
    sender.send(**op)
    [status] = sender.statuses()
    assert status["level"] == "error" and f"at {field or '$.status'}" in str(status["msg"])
    if field == "$.id":
        assert "id" not in status  # an id out of range is not echoed
    still_served(sender, other)


def cbor_frame(peer: Peer, op: dict[str, Any]) -> None:
    peer.session.receive_frame(cbor2.dumps(op), peer.clock.monotonic(), binary=True)


@pytest.mark.parametrize(
    "op",
    [
        {"op": "call_service", "service": "/rosapi/topics", "id": 10**5000},
        {"op": "subscribe", "topic": "/probe", "id": 10**5000},
        {"op": "publish", "topic": "/probe", "msg": {"data": "x"}, "id": -(10**5000)},
        {"op": "subscribe", "topic": "/probe", "throttle_rate": 10**5000},
        {"op": "publish", "topic": "/ints", "msg": {"data": 10**5000}},
    ],
    ids=["call_service-id", "subscribe-id", "publish-id", "throttle_rate", "msg-field"],
)
def test_a_cbor_integer_too_large_to_print_is_refused(graph: Graph, op: dict[str, Any]) -> None:
    install_rosapi(graph)
    sender, other = pair(graph)
    sender.send(op="advertise", topic="/ints", type="std_msgs/Int64")
    cbor_frame(sender, op)  # must not raise
    [text] = error_texts(sender)
    assert "integer out of range" in text
    still_served(sender, other)


def test_an_unencodable_reply_becomes_a_failure_reply(graph: Graph) -> None:
    graph.create_service("/bad", TRIGGER, lambda req: {"message": LONE})
    caller, other = pair(graph)
    caller.send(op="call_service", service="/bad", id="b")
    caller.send(op="call_service", service="/bad", id="c", compression="cbor")
    for reply in [json.loads(f.data) for f in caller.session.frames_to_send()]:
        assert reply["op"] == "service_response" and reply["result"] is False
        assert reply["values"].startswith("cannot encode the service_response: ")
        assert reply["service"] == "/bad" and reply["id"] in ("b", "c")
    still_served(caller, other)


def test_a_caller_with_a_timeout_hears_back_when_the_provider_answers_garbage(
    graph: Graph, clock: FakeClock
) -> None:
    provider, caller = Peer(graph, "p"), Peer(graph, "c")
    provider.send(op="advertise_service", service="/trig", type=TRIGGER)
    caller.send(op="call_service", service="/trig", id="t", timeout=2.0)
    [request] = provider.received()
    provider.send(
        op="service_response",
        service="/trig",
        id=request["id"],
        result=True,
        values={"success": True, "message": LONE},
    )
    assert "lone surrogate" in error_texts(provider)[0]
    caller.session.handle_timer(clock.now + 2.0)
    [reply] = caller.received()
    assert reply["id"] == "t" and reply["result"] is False
    assert "timed out" in str(reply["values"])


def test_rosapi_listings_still_answer_after_bad_names(graph: Graph) -> None:
    install_rosapi(graph)
    web, other = connect(graph, "web"), connect(graph, "other")
    web.send(op="advertise", topic=f"/bad{LONE}", type="std_msgs/String")
    web.send(op="advertise_service", service=f"/bad{LONE}", type=TRIGGER)
    web.send(op="call_service", service="/rosapi/set_param", args={"name": f"/x:{LONE}"})
    web.send(op="call_service", service="/rosapi/set_param", args={"name": "/x:" + "p" * 2000})
    web.received()
    # In-process code is not checked at the edge: its bad name is left out of listings.
    graph.create_publisher(f"/inproc{LONE}", "std_msgs/String")
    assert call(other, "/rosapi/topics")["topics"] == []
    assert all(LONE not in name for name in call(other, "/rosapi/services")["services"])
    assert call(other, "/rosapi/get_param_names")["names"] == []
    assert all(LONE not in node for node in call(other, "/rosapi/nodes")["nodes"])


def test_a_provider_disconnect_leaves_no_zombie_even_if_a_step_fails(
    graph: Graph, caplog: pytest.LogCaptureFixture
) -> None:
    provider = Peer(graph, "p")
    provider.send(op="advertise_service", service="/svc", type=TRIGGER)
    provider.send(op="advertise_action", action="/fib", type=FIB)
    provider.send(op="advertise", topic="/pub", type="std_msgs/String")

    def broken_reply(result: bool, values: object) -> None:
        raise RuntimeError("a caller's reply failed")

    graph.port.call_service("local:caller", "/svc", {}, broken_reply)
    provider.received()
    provider.session.close()  # must not raise
    assert "/svc" not in graph.services.entries
    assert "/fib" not in graph.actions.entries
    assert "/pub" not in graph.topics
    assert "a caller's reply failed" in caplog.text


def test_a_bug_is_logged_once_and_reported_every_time(
    graph: Graph, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def broken(session: object, op: object, now: float) -> None:
        raise RuntimeError("bug")

    monkeypatch.setitem(handlers.HANDLERS, ops.SetLevel, broken)
    sender, other = pair(graph)
    with caplog.at_level(logging.INFO, logger="rwt.session"):
        for n in range(3):
            sender.send(op="set_level", level="info", id=n)
    assert [m["msg"] for m in sender.statuses()] == ["set_level: internal error"] * 3
    assert len([r for r in caplog.records if r.exc_info]) == 1
    still_served(sender, other)


def test_an_unencodable_message_from_in_process_code_is_reported_and_logged_once(
    graph: Graph, caplog: pytest.LogCaptureFixture
) -> None:
    publisher = graph.create_publisher("/inproc", "std_msgs/String")
    subscriber, other = pair(graph)
    subscriber.send(op="subscribe", topic="/inproc")
    with caplog.at_level(logging.DEBUG, logger="rwt.session"):
        for _ in range(3):
            publisher.publish({"data": LONE})
    statuses = subscriber.statuses()
    assert [s["msg"] for s in statuses] == [
        "subscribe: cannot send a message of /inproc as none"
    ] * 3
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and not warnings[0].exc_info
    assert "event=unencodable" in warnings[0].getMessage()
    publisher.publish({"data": "fine"})
    assert subscriber.received() == [{"op": "publish", "topic": "/inproc", "msg": {"data": "fine"}}]
    still_served(subscriber, other)


def test_cesu8_surrogate_bytes_are_not_utf8() -> None:
    # json.loads would decode these bytes into a lone surrogate; the frame is refused.
    peer = Peer(Graph(clock=FakeClock()), "c")
    peer.send_raw(b'{"op":"set_level","level":"info","id":"\xed\xa0\x80"}')
    [status] = peer.received()
    assert status["level"] == "error" and "not UTF-8" in status["msg"]
