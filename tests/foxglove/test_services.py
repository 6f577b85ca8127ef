"""Foxglove service calls without I/O: the graph's services as a client sees and calls them."""

from __future__ import annotations

import struct

import pytest

from rwt_foxglove.wire import decode_wire
from rwt_graph.graph import Graph
from rwt_graph.rosapi import install_rosapi
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.runtime.rules import ClientRules
from tests.conftest import Peer
from tests.foxglove.sansio import Client, cdr

ADD = "example_interfaces/srv/AddTwoInts"
BIG = 2**62 + 1  # past 2^53: a float would round it


def _sum(graph: Graph, payload: bytes) -> object:
    mtype = graph.registry.message(f"{ADD}_Response")
    return decode_wire(graph.registry, mtype, payload)["sum"]


def _request(graph: Graph, a: int, b: int) -> bytes:
    return cdr(graph, f"{ADD}_Request", {"a": a, "b": b})


def _failures(client: Client) -> list[tuple[int, int, str]]:
    return [
        (int(op["serviceId"]), int(op["callId"]), str(op["message"]))  # type: ignore[call-overload]
        for op in client.take_ops("serviceCallFailure")
    ]


def _rosbridge_adder(graph: Graph, name: str = "/rb_add") -> Peer:
    peer = Peer(graph, "rb")
    peer.send(op="advertise_service", service=name, type=ADD)
    assert peer.statuses() == []
    return peer


def test_services_of_every_provider_are_advertised_with_their_schemas(graph: Graph) -> None:
    graph.create_service("/local_add", ADD, lambda req: {"sum": req["a"] + req["b"]})
    _rosbridge_adder(graph)
    install_rosapi(graph)
    client = Client(graph, show_plumbing=True)  # rosapi's services too (test_plumbing.py)
    for name in ("/local_add", "/rb_add"):
        service = client.service(name)
        assert service["type"] == ADD
        assert "requestSchema" not in service and "responseSchema" not in service  # deprecated
        request = service["request"]
        assert request == {  # type: ignore[comparison-overlap]
            "encoding": "cdr",
            "schemaName": f"{ADD}_Request",
            "schemaEncoding": "ros2msg",
            "schema": request["schema"],  # type: ignore[index]
        }
        assert "int64 a\nint64 b\n" in str(request["schema"])  # type: ignore[index]
        assert "int64 sum\n" in str(service["response"]["schema"])  # type: ignore[index]
        assert service["response"]["schemaName"] == f"{ADD}_Response"  # type: ignore[index]
    assert client.service("/rosapi/topics")["type"] == "rosapi_msgs/srv/Topics"
    ids = [
        service["id"] for op in client.take_ops("advertiseServices") for service in op["services"]
    ]  # type: ignore[attr-defined]
    assert len(ids) == len(set(ids))


def test_a_call_is_answered_in_cdr_with_int64_exact(graph: Graph) -> None:
    graph.create_service("/local_add", ADD, lambda req: {"sum": req["a"] + req["b"]})
    client = Client(graph)
    sid = int(client.service("/local_add")["id"])  # type: ignore[call-overload]
    client.call(sid, 7, _request(graph, BIG, 2))
    [(service_id, call_id, encoding, payload)] = client.responses()
    assert (service_id, call_id, encoding) == (sid, 7, "cdr")
    assert _sum(graph, payload) == BIG + 2


def test_concurrent_calls_to_a_rosbridge_provider_are_answered_by_call_id(graph: Graph) -> None:
    peer = _rosbridge_adder(graph)
    client = Client(graph)
    sid = int(client.service("/rb_add")["id"])  # type: ignore[call-overload]
    client.call(sid, 1, _request(graph, BIG, 1))
    client.call(sid, 2, _request(graph, 10, 20))
    requests = [op for op in peer.received() if op["op"] == "call_service"]
    assert [op["args"] for op in requests] == [{"a": BIG, "b": 1}, {"a": 10, "b": 20}]
    for op in reversed(requests):  # the provider answers the second first
        args = op["args"]
        peer.send(
            op="service_response",
            service="/rb_add",
            id=op["id"],
            result=True,
            values={"sum": args["a"] + args["b"]},  # type: ignore[index]
        )
    client.drain()
    got = [(call_id, _sum(graph, payload)) for _, call_id, _, payload in client.responses()]
    assert got == [(2, 30), (1, BIG + 1)]


def test_failures_come_by_call_id_and_the_session_goes_on(graph: Graph) -> None:
    peer = _rosbridge_adder(graph)
    graph.create_service("/local_add", ADD, lambda req: {"sum": req["a"] + req["b"]})
    client = Client(graph, config=ClientRules(max_pending_calls=2))  # --max-pending-calls
    sid = int(client.service("/rb_add")["id"])  # type: ignore[call-overload]
    local = int(client.service("/local_add")["id"])  # type: ignore[call-overload]
    client.call(9999, 1, _request(graph, 1, 2))
    client.call(local, 2, _request(graph, 1, 2), encoding="json")
    client.call(local, 3, b"\x00\x01\x00\x00\x01")  # the CDR header, then too few bytes
    client.call(sid, 4, _request(graph, 1, 1))
    client.call(sid, 4, _request(graph, 1, 1))  # that id is in flight
    client.call(sid, 5, _request(graph, 1, 1))
    client.call(sid, 6, _request(graph, 1, 1))  # a third in flight
    failures = _failures(client)
    assert [(s, c) for s, c, _ in failures] == [
        (9999, 1),
        (local, 2),
        (local, 3),
        (sid, 4),
        (sid, 6),
    ]
    texts = [text for _, _, text in failures]
    assert "unknown service 9999" in texts[0]
    assert "unsupported encoding 'json' (expected cdr)" in texts[1]
    assert "bad request" in texts[2] and "AddTwoInts_Request" in texts[2]
    assert "call id 4 is already in flight" in texts[3]
    assert "too many calls in flight (at most 2)" in texts[4]
    requests = [op for op in peer.received() if op["op"] == "call_service"]
    assert len(requests) == 2
    peer.send(
        op="service_response", service="/rb_add", id=requests[0]["id"], result=False, values="no"
    )
    client.drain()
    assert _failures(client) == [(sid, 4, "no")]
    peer.session.close()  # the provider goes: its last call fails
    client.drain()
    [(service_id, call_id, text)] = _failures(client)
    assert (service_id, call_id) == (sid, 5) and "provider disconnected" in text
    client.call(local, 8, _request(graph, 3, 4))  # the session goes on
    assert [_sum(graph, payload) for *_, payload in client.responses()] == [7]


def test_a_call_without_answer_times_out_and_a_late_answer_goes_nowhere(graph: Graph) -> None:
    """``--call-timeout`` binds a Foxglove client's calls, on a timer of their own."""
    peer = _rosbridge_adder(graph)
    client = Client(graph, config=ClientRules(call_timeout_s=5.0))
    sid = int(client.service("/rb_add")["id"])  # type: ignore[call-overload]
    client.now = 100.0
    client.call(sid, 1, _request(graph, 1, 2))
    assert client.session.get_timer() == 105.0  # its deadline: no polling
    client.sync(104.999)
    assert _failures(client) == []
    client.sync(105.0)
    assert _failures(client) == [(sid, 1, "no response within 5 s")]
    [request] = [op for op in peer.received() if op["op"] == "call_service"]
    peer.send(
        op="service_response", service="/rb_add", id=request["id"], result=True, values={"sum": 3}
    )
    client.drain()
    assert client.responses() == [] and _failures(client) == []


def test_services_that_go_or_change_type_are_unadvertised(graph: Graph) -> None:
    peer = _rosbridge_adder(graph)
    client = Client(graph)
    sid = client.service("/rb_add")["id"]
    peer.send(op="unadvertise_service", service="/rb_add")
    client.sync()
    assert client.take_ops("unadvertiseServices") == [
        {"op": "unadvertiseServices", "serviceIds": [sid]}
    ]
    client.ops = []
    peer.send(op="advertise_service", service="/rb_add", type="std_srvs/srv/SetBool")
    client.sync()
    again = client.service("/rb_add")
    assert again["type"] == "std_srvs/srv/SetBool" and again["id"] != sid
    client.ops = []
    _rosbridge_adder(graph)  # another provider takes the name with another type
    client.sync()
    assert client.take_ops("unadvertiseServices") == [
        {"op": "unadvertiseServices", "serviceIds": [again["id"]]}
    ]
    assert client.service("/rb_add")["type"] == ADD
    client.call(int(sid), 1, _request(graph, 1, 2))  # type: ignore[call-overload]
    assert "unknown service" in _failures(client)[0][2]


def test_access_globs_hide_services(graph: Graph) -> None:
    _rosbridge_adder(graph, "/public/add")
    _rosbridge_adder(graph, "/secret/add")
    client = Client(graph, access=AccessPolicy(services=("/public/*",)))
    client.service("/public/add")
    with pytest.raises(AssertionError):
        client.service("/secret/add")


def test_a_closed_session_forgets_its_calls(graph: Graph) -> None:
    peer = _rosbridge_adder(graph)
    client = Client(graph)
    sid = int(client.service("/rb_add")["id"])  # type: ignore[call-overload]
    client.call(sid, 1, _request(graph, 1, 2))
    client.session.close()
    [request] = [op for op in peer.received() if op["op"] == "call_service"]
    peer.send(
        op="service_response", service="/rb_add", id=request["id"], result=True, values={"sum": 3}
    )
    assert client.session.frames_to_send() == []


def test_a_ros1_graph_calls_in_the_ros1_serialization() -> None:
    ros1 = Graph(TypeRegistry(Dialect.ROS1))
    ros1.create_service(
        "/switch", "std_srvs/SetBool", lambda req: {"success": req["data"], "message": "on"}
    )
    client = Client(ros1)
    service = client.service("/switch")
    assert service["request"]["encoding"] == "ros1"  # type: ignore[index]
    assert service["request"]["schemaName"] == "std_srvs/SetBoolRequest"  # type: ignore[index]
    assert service["request"]["schemaEncoding"] == "ros1msg"  # type: ignore[index]
    client.call(int(service["id"]), 1, b"\x01", encoding="ros1")  # type: ignore[call-overload]
    [(_, call_id, encoding, payload)] = client.responses()
    assert (call_id, encoding) == (1, "ros1")
    assert payload == b"\x01" + struct.pack("<I", 2) + b"on"
