"""The call book every protocol's session keeps: a cap, a deadline each, one answer.

A rosbridge ``call_service`` and a Foxglove ``serviceCallRequest`` both go
through ``SessionBase.calls`` (rwt_protocol/runtime/callbook.py); here the
rosbridge side, through a session, against a provider that never answers.
"""

from __future__ import annotations

from rwt_graph.graph import Graph
from rwt_protocol.server.session import Session, SessionConfig
from tests.conftest import Peer

ADD = "example_interfaces/srv/AddTwoInts"


def _caller(graph: Graph, **config: object) -> Peer:
    peer = Peer(graph, "caller")
    peer.session = Session(graph.port, "caller", config=SessionConfig(**config))  # type: ignore[arg-type]
    return peer


def _silent_provider(graph: Graph) -> Peer:
    provider = Peer(graph, "provider")
    provider.send(op="advertise_service", service="/add", type=ADD)
    return provider


def test_a_call_has_a_deadline_timer_of_its_own_and_is_answered_once(graph: Graph) -> None:
    provider = _silent_provider(graph)
    caller = _caller(graph, call_timeout_s=2.0)
    now = graph.clock.monotonic()
    caller.send(op="call_service", service="/add", args={"a": 1, "b": 2}, id="c1")
    assert caller.session.calls.in_flight == 1
    assert caller.session.get_timer() == now + 2.0  # the deadline itself: no poll
    caller.session.handle_timer(now + 2.0)
    [reply] = caller.received()
    assert (reply["op"], reply["result"], reply["id"]) == ("service_response", False, "c1")
    assert reply["values"] == "service call timed out after 2 s"
    assert caller.session.calls.in_flight == 0
    [request] = provider.received()  # the provider answers late: it goes nowhere
    provider.send(
        op="service_response", service="/add", id=request["id"], result=True, values={"sum": 3}
    )
    assert caller.received() == []


def test_the_cap_refuses_the_call_past_it_with_an_answer(graph: Graph) -> None:
    _silent_provider(graph)
    caller = _caller(graph, max_pending_calls=2)
    for n in range(3):
        caller.send(op="call_service", service="/add", args={"a": n, "b": 0}, id=f"c{n}")
    replies = [op for op in caller.received() if op["op"] == "service_response"]
    assert [(op["id"], op["result"]) for op in replies] == [("c2", False)]
    assert caller.session.calls.in_flight == 2


def test_closing_settles_every_call(graph: Graph) -> None:
    provider = _silent_provider(graph)
    caller = _caller(graph)
    caller.send(op="call_service", service="/add", args={"a": 1, "b": 2}, id="c1")
    caller.session.close()
    assert caller.session.calls.in_flight == 0
    [request] = provider.received()
    provider.send(
        op="service_response", service="/add", id=request["id"], result=True, values={"sum": 3}
    )
    assert provider.received() == []  # taken without error, and it went nowhere
    assert caller.session.frames_to_send() == []
