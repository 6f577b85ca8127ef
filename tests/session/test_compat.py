"""``--compat rosbridge``: what a client written against rosbridge_suite sees (docs/differences.md).

rosbridge_suite 2.1.0 sends no ``status`` op and answers a missing service with its
own text (docs/reference-behaviour.md, ``call_service`` and ``set_level``); rwt's
default reports every refusal (D1-D4).
"""

from __future__ import annotations

import json

import pytest

from rwt_graph.graph import Graph
from rwt_protocol.server.compat import Compat
from rwt_protocol.server.session import Session, SessionConfig

REFUSED = [
    {"op": "subscribe", "topic": "/a", "type": "no_such_pkg/msg/Nope"},
    {"op": "publish", "topic": "/b", "msg": {"data": 1}},
    {"op": "advertise", "topic": "/c", "type": "not a type"},
    {"op": "no_such_op"},
    {"op": "subscribe", "topic": "/a", "throttle_rate": "fast"},
]


def session(graph: Graph, compat: Compat) -> Session:
    return Session(graph.port, f"{compat}-client", config=SessionConfig(compat=compat))


def exchange(client: Session, *ops: dict[str, object]) -> list[dict[str, object]]:
    for op in ops:
        client.receive_frame(json.dumps(op), 0.0)
    return [json.loads(frame.data) for frame in client.frames_to_send()]


@pytest.mark.parametrize("op", REFUSED, ids=lambda op: str(op["op"]))
def test_a_refused_op_gets_no_status_until_the_client_asks(graph: Graph, op: dict) -> None:
    client = session(graph, Compat.ROSBRIDGE)
    assert exchange(client, op) == []
    [status] = exchange(client, {"op": "set_level", "level": "error"}, op)
    assert status["op"] == "status" and status["level"] == "error"


@pytest.mark.parametrize("op", REFUSED, ids=lambda op: str(op["op"]))
def test_rwt_reports_the_same_op_at_once(graph: Graph, op: dict) -> None:
    [status] = exchange(session(graph, Compat.RWT), op)
    assert status["op"] == "status" and status["level"] == "error"


def test_a_missing_service_is_answered_in_rosbridge_suites_words(graph: Graph) -> None:
    call = {"op": "call_service", "service": "/nope", "id": "c1"}
    assert exchange(session(graph, Compat.ROSBRIDGE), call) == [
        {
            "op": "service_response",
            "service": "/nope",
            "values": "Service /nope does not exist",
            "result": False,
            "id": "c1",
        }
    ]
    reply, status = exchange(session(graph, Compat.RWT), call)
    assert reply["values"] == "service /nope does not exist"
    assert status["op"] == "status"


def test_other_failure_texts_stay_rwts(graph: Graph) -> None:
    # rosbridge_suite's texts for these depend on its Python classes: not imitated
    graph.create_service("/set", "std_srvs/srv/SetBool", lambda request: {})
    bad = {"op": "call_service", "service": "/set", "args": {"data": 2}, "id": "c2"}
    [reply] = exchange(session(graph, Compat.ROSBRIDGE), bad)
    assert reply["result"] is False
    assert "$.args.data" in str(reply["values"])


@pytest.mark.parametrize(
    ("compat", "text"),
    [
        (Compat.ROSBRIDGE, "Service /later does not exist"),
        (Compat.RWT, "service /later does not exist"),
    ],
)
def test_a_call_that_waited_for_discovery_in_vain_gets_the_modes_text(
    graph: Graph, compat: Compat, text: str
) -> None:
    # a link (the ROS 2 one) may still discover the service: the call waits, and
    # when the link's wait ends without it the reply comes later, from the graph
    waits: list = []
    graph.services.discoveries.append(lambda expire: waits.append(expire) or (lambda: None))
    client = session(graph, compat)
    call = {"op": "call_service", "service": "/later#c3"}
    assert exchange(client, call) == []  # held, not refused
    [expire] = waits
    expire()
    [reply] = exchange(client)
    assert reply == {
        "op": "service_response",
        "service": "/later#c3",
        "values": text,
        "result": False,
        "id": "c3",
    }
