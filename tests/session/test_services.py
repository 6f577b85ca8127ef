"""Services through sessions on one graph: routing, timeouts, cleanup (spec 3.3.6-3.3.9).

D4, D15-D17, D25, D26, D28; REF §2.6-2.10, §6.1, §8 W2-W4, L13-L21.
"""

from __future__ import annotations

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.server.session import Session, SessionConfig
from tests.conftest import FakeClock, Peer


def advertise_set_bool(peer: Peer, name: str = "/set_bool") -> None:
    peer.send(op="advertise_service", service=name, type="std_srvs/SetBool")


def test_call_is_forwarded_and_the_answer_routed_back(peers: tuple[Peer, Peer]) -> None:
    provider, caller = peers
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool", args={"data": True}, id="c1")
    [request] = provider.received()
    assert request == {
        "op": "call_service",
        "id": "service_request:/set_bool:1",
        "service": "/set_bool",
        "args": {"data": True},
    }
    provider.send(
        op="service_response",
        service="/set_bool",
        id=request["id"],
        values={"success": True, "message": "set"},
        result=True,
    )
    assert caller.received() == [
        {
            "op": "service_response",
            "service": "/set_bool",
            "values": {"success": True, "message": "set"},
            "result": True,
            "id": "c1",
        }
    ]


def test_concurrent_calls_answered_out_of_order_reach_their_callers(graph: Graph) -> None:
    provider = Peer(graph, "p")
    callers = [Peer(graph, f"c{i}") for i in range(12)]
    provider.send(op="advertise_service", service="add", type="example_interfaces/AddTwoInts")
    for i, caller in enumerate(callers):
        caller.send(op="call_service", service="/add", args=[i, 100], id=i)
    requests = provider.received()
    assert [r["id"] for r in requests] == [f"service_request:add:{n}" for n in range(1, 13)]
    for request in reversed(requests):
        args = request["args"]
        provider.send(
            op="service_response",
            service="add",
            id=request["id"],
            values={"sum": args["a"] + args["b"]},
            result=True,
        )
    for i, caller in enumerate(callers):
        [reply] = caller.received()
        assert reply["id"] == i and reply["values"] == {"sum": i + 100}


def test_caller_spelling_and_legacy_hash_id_are_echoed(peers: tuple[Peer, Peer]) -> None:
    provider, caller = peers
    advertise_set_bool(provider, "set_bool")
    caller.send(op="call_service", service="/set_bool#33", args={"data": False})
    [request] = provider.received()
    assert request["service"] == "set_bool"
    provider.send(
        op="service_response", service="set_bool", id=request["id"], values={}, result=True
    )
    [reply] = caller.received()
    assert reply["id"] == "33"
    assert reply["service"] == "/set_bool#33"
    assert reply["values"] == {"success": False, "message": ""}


def test_empty_response_carries_empty_values_object(peers: tuple[Peer, Peer]) -> None:
    provider, caller = peers
    provider.send(op="advertise_service", service="/e", type="std_srvs/Empty")
    caller.send(op="call_service", service="/e")
    [request] = provider.received()
    assert request["args"] == {}
    provider.send(op="service_response", service="/e", id=request["id"], result=True)
    assert caller.received() == [
        {"op": "service_response", "service": "/e", "values": {}, "result": True}
    ]


def test_unknown_service_fails_at_once_with_a_reply_and_a_status(
    peers: tuple[Peer, Peer],
) -> None:
    _, caller = peers
    caller.send(op="call_service", service="/nope", id=5)
    reply, status = caller.received()
    assert reply["op"] == "service_response" and reply["result"] is False
    assert reply["id"] == 5 and "does not exist" in str(reply["values"])
    assert status["op"] == "status" and status["id"] == 5


def test_bad_args_fail_with_the_field_path(peers: tuple[Peer, Peer]) -> None:
    provider, caller = peers
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool", args={"data": 42.0})
    reply, _status = caller.received()
    assert reply["result"] is False and "$.args.data" in str(reply["values"])
    assert provider.received() == []


def test_provider_failure_reaches_the_caller_as_text(peers: tuple[Peer, Peer]) -> None:
    provider, caller = peers
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool", id="x")
    [request] = provider.received()
    provider.send(
        op="service_response", service="/set_bool", id=request["id"], values="no", result=False
    )
    [reply] = caller.received()
    assert reply == {
        "op": "service_response",
        "service": "/set_bool",
        "values": "no",
        "result": False,
        "id": "x",
    }


def test_invalid_response_fails_the_caller_and_tells_the_provider(
    peers: tuple[Peer, Peer],
) -> None:
    provider, caller = peers
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool")
    [request] = provider.received()
    provider.send(
        op="service_response",
        service="/set_bool",
        id=request["id"],
        values={"success": 1},
        result=True,
    )
    [reply] = caller.received()
    assert reply["result"] is False and "$.values.success" in str(reply["values"])
    assert "$.values.success" in str(provider.statuses()[0]["msg"])


def test_call_times_out_by_its_own_timeout(peers: tuple[Peer, Peer], clock: FakeClock) -> None:
    provider, caller = peers
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool", id="t", timeout=2.0)
    assert caller.session.get_timer() == clock.now + 2.0
    caller.session.handle_timer(clock.now + 1.9)
    assert caller.received() == []
    caller.session.handle_timer(clock.now + 2.0)
    [reply] = caller.received()
    assert reply["result"] is False and "timed out" in str(reply["values"])
    [request] = provider.received()
    provider.send(
        op="service_response", service="/set_bool", id=request["id"], result=True, values={}
    )
    assert caller.received() == []


def test_call_times_out_by_the_server_default(graph: Graph, clock: FakeClock) -> None:
    provider = Peer(graph, "p")
    advertise_set_bool(provider)
    caller = Session(graph.port, "c", config=SessionConfig(call_timeout_s=5.0))
    caller.receive_frame('{"op":"call_service","service":"/set_bool"}', clock.now)
    assert caller.get_timer() == clock.now + 5.0


def test_answered_call_cancels_its_timer(peers: tuple[Peer, Peer]) -> None:
    provider, caller = peers
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool", timeout=1.0)
    [request] = provider.received()
    provider.send(
        op="service_response", service="/set_bool", id=request["id"], result=True, values={}
    )
    assert caller.session.get_timer() is None


def test_provider_disconnect_fails_pending_calls(graph: Graph) -> None:
    provider, caller = Peer(graph, "p"), Peer(graph, "c")
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool", id=1)
    caller.send(op="call_service", service="/set_bool", id=2)
    provider.session.close()
    replies = caller.received()
    assert [(r["id"], r["result"]) for r in replies] == [(1, False), (2, False)]
    caller.send(op="call_service", service="/set_bool", id=3)
    assert "does not exist" in str(caller.received()[0]["values"])


def test_unadvertise_fails_pending_calls(peers: tuple[Peer, Peer]) -> None:
    provider, caller = peers
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool")
    provider.send(op="unadvertise_service", service="/set_bool")
    [reply] = caller.received()
    assert reply["result"] is False and "unadvertised" in str(reply["values"])


def test_newest_advertiser_wins_and_counter_restarts(graph: Graph) -> None:
    old = Peer(graph, "old", level=StatusLevel.WARNING)
    new, caller = Peer(graph, "new"), Peer(graph, "c")
    advertise_set_bool(old)
    caller.send(op="call_service", service="/set_bool", id="first")
    advertise_set_bool(new)
    [failed] = caller.received()
    assert failed["id"] == "first" and failed["result"] is False
    assert any(m["op"] == "status" and m["level"] == "warning" for m in old.received())
    caller.send(op="call_service", service="/set_bool", id="second")
    [request] = new.received()
    assert request["id"] == "service_request:/set_bool:1"


def test_only_the_advertiser_may_answer(graph: Graph) -> None:
    provider, intruder, caller = Peer(graph, "p"), Peer(graph, "i"), Peer(graph, "c")
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool")
    [request] = provider.received()
    intruder.send(
        op="service_response", service="/set_bool", id=request["id"], result=True, values={}
    )
    assert intruder.statuses()[0]["level"] == "error"
    assert caller.received() == []
    intruder.send(op="unadvertise_service", service="/set_bool")
    assert intruder.statuses()[0]["level"] == "error"


def test_a_client_may_call_its_own_service(peers: tuple[Peer, Peer]) -> None:
    provider, _ = peers
    advertise_set_bool(provider)
    provider.send(op="call_service", service="/set_bool", id="self", args=[True])
    [request] = provider.received()
    provider.send(
        op="service_response",
        service="/set_bool",
        id=request["id"],
        result=True,
        values={"success": True},
    )
    [reply] = provider.received()
    assert reply["id"] == "self" and reply["values"]["success"] is True


def test_caller_disconnect_drops_its_pending_calls(graph: Graph) -> None:
    provider, caller = Peer(graph, "p"), Peer(graph, "c", level=StatusLevel.WARNING)
    advertise_set_bool(provider)
    caller.send(op="call_service", service="/set_bool")
    caller.session.close()
    [request] = provider.received()
    provider.session.set_status_level(StatusLevel.WARNING)
    provider.send(
        op="service_response", service="/set_bool", id=request["id"], result=True, values={}
    )
    assert provider.statuses()[0]["level"] == "warning"


def test_in_process_service_answers_clients(graph: Graph) -> None:
    graph.create_service(
        "/trigger", "std_srvs/srv/Trigger", lambda request: {"success": True, "message": "done"}
    )
    graph.create_service("/boom", "std_srvs/srv/Trigger", lambda request: 1 / 0)
    caller = Peer(graph, "c")
    caller.send(op="call_service", service="trigger", id=1)
    caller.send(op="call_service", service="/boom", id=2)
    ok, failed = caller.received()
    assert ok["values"] == {"success": True, "message": "done"} and ok["result"] is True
    assert failed["result"] is False and "division by zero" in str(failed["values"])


def test_positional_args_and_their_limits(graph: Graph) -> None:
    seen: list[dict[str, object]] = []
    graph.create_service(
        "/add", "example_interfaces/srv/AddTwoInts", lambda r: seen.append(r) or {"sum": 0}
    )
    caller = Peer(graph, "c")
    caller.send(op="call_service", service="/add", args=[3])
    caller.send(op="call_service", service="/add", args=[1, 2, 3])
    caller.send(op="call_service", service="/add", args="text")
    assert seen == [{"a": 3, "b": 0}]
    results = [m for m in caller.received() if m["op"] == "service_response"]
    assert [r["result"] for r in results] == [True, False, False]
