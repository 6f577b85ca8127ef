"""Actions through sessions on one graph (spec 3.3.10-3.3.15, D4, D15, D18; REF §6.3, W9-W11)."""

from __future__ import annotations

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from tests.conftest import Peer

FIB = "example_interfaces/action/Fibonacci"


def test_goal_feedback_and_result_flow_between_clients(peers: tuple[Peer, Peer]) -> None:
    server, client = peers
    server.send(op="advertise_action", action="/fib", type=FIB)
    client.send(
        op="send_action_goal",
        action="/fib",
        action_type=FIB,
        args={"order": 3},
        feedback=True,
        id="g1",
    )
    [goal] = server.received()
    assert goal == {
        "op": "send_action_goal",
        "id": "action_goal:/fib:1",
        "action": "/fib",
        "action_type": FIB,
        "args": {"order": 3},
        "feedback": True,
    }
    server.send(op="action_feedback", action="/fib", id=goal["id"], values={"sequence": [0, 1]})
    server.send(
        op="action_result",
        action="/fib",
        id=goal["id"],
        values={"sequence": [0, 1, 1]},
        status=4,
        result=True,
    )
    assert client.received() == [
        {"op": "action_feedback", "action": "/fib", "values": {"sequence": [0, 1]}, "id": "g1"},
        {
            "op": "action_result",
            "action": "/fib",
            "values": {"sequence": [0, 1, 1]},
            "status": 4,
            "result": True,
            "id": "g1",
        },
    ]


def test_feedback_only_when_asked(peers: tuple[Peer, Peer]) -> None:
    server, client = peers
    server.send(op="advertise_action", action="/fib", type=FIB)
    client.send(op="send_action_goal", action="/fib", action_type=FIB, args={"order": 1})
    [goal] = server.received()
    server.send(op="action_feedback", action="/fib", id=goal["id"], values={"sequence": [0]})
    server.send(op="action_result", action="/fib", id=goal["id"], values={}, result=True)
    [result] = client.received()
    assert result["op"] == "action_result" and result["status"] == 4


def test_result_without_status_defaults_per_d18(peers: tuple[Peer, Peer]) -> None:
    server, client = peers
    server.send(op="advertise_action", action="/fib", type=FIB)
    client.send(op="send_action_goal", action="/fib", action_type=FIB, id=1)
    client.send(op="send_action_goal", action="/fib", action_type=FIB, id=2)
    first, second = server.received()
    server.send(op="action_result", action="/fib", id=second["id"], result=False, values={})
    server.send(
        op="action_result", action="/fib", id=first["id"], result=True, values={"sequence": [0]}
    )
    done = {r["id"]: (r["status"], r["result"]) for r in client.received()}
    assert done == {2: (6, True), 1: (4, True)}


def test_cancel_is_forwarded_and_the_canceled_result_returned(peers: tuple[Peer, Peer]) -> None:
    server, client = peers
    server.send(op="advertise_action", action="fib", type=FIB)
    client.send(op="send_action_goal", action="/fib", action_type=FIB, args=[5], id="g")
    [goal] = server.received()
    client.send(op="cancel_action_goal", action="/fib", id="g")
    assert server.received() == [{"op": "cancel_action_goal", "id": goal["id"], "action": "fib"}]
    server.send(
        op="action_result",
        action="fib",
        id=goal["id"],
        status=5,
        result=True,
        values={"sequence": []},
    )
    [result] = client.received()
    assert (result["status"], result["values"], result["action"]) == (5, {"sequence": []}, "/fib")


def test_goal_to_an_unknown_action_is_aborted_at_once(peers: tuple[Peer, Peer]) -> None:
    _, client = peers
    client.send(op="send_action_goal", action="/none", action_type=FIB, id="g")
    result, status = client.received()
    assert result["op"] == "action_result" and result["result"] is False
    assert result["status"] == 6 and result["id"] == "g"
    assert status["op"] == "status"


def test_provider_disconnect_aborts_goals(graph: Graph) -> None:
    server, client = Peer(graph, "s"), Peer(graph, "c")
    server.send(op="advertise_action", action="/fib", type=FIB)
    client.send(op="send_action_goal", action="/fib", action_type=FIB, id="g")
    server.session.close()
    [result] = client.received()
    assert (result["status"], result["result"]) == (6, False)


def test_two_concurrent_goals_answered_independently(peers: tuple[Peer, Peer]) -> None:
    server, client = peers
    server.send(op="advertise_action", action="/fib", type=FIB)
    client.send(op="send_action_goal", action="/fib", action_type=FIB, args={"order": 3}, id=3)
    client.send(op="send_action_goal", action="/fib", action_type=FIB, args={"order": 5}, id=5)
    goals = server.received()
    assert [g["id"] for g in goals] == ["action_goal:/fib:1", "action_goal:/fib:2"]
    server.send(
        op="action_result",
        action="/fib",
        id=goals[1]["id"],
        status=4,
        result=True,
        values={"sequence": [0, 1, 1, 2, 3, 5]},
    )
    server.send(
        op="action_result",
        action="/fib",
        id=goals[0]["id"],
        status=4,
        result=True,
        values={"sequence": [0, 1, 1, 2]},
    )
    got = {r["id"]: r["values"]["sequence"] for r in client.received()}
    assert got == {5: [0, 1, 1, 2, 3, 5], 3: [0, 1, 1, 2]}


def test_bad_feedback_and_unknown_goal_get_statuses(peers: tuple[Peer, Peer]) -> None:
    server, client = peers
    server.send(op="advertise_action", action="/fib", type=FIB)
    client.send(op="send_action_goal", action="/fib", action_type=FIB, feedback=True)
    [goal] = server.received()
    server.send(op="action_feedback", action="/fib", id=goal["id"], values={"sequence": "x"})
    server.send(op="action_result", action="/fib", id="action_goal:/fib:99", result=True, status=4)
    server.send(op="action_result", action="/fib", id=goal["id"], result=True, status=2)
    texts = [str(s["msg"]) for s in server.statuses()]
    assert "$.values.sequence" in texts[0]
    assert len(texts) == 2  # the unknown goal id is a warning, below the default level
    assert "not terminal" in texts[1]
    assert client.received() == []


def test_cancel_of_an_unknown_goal_warns(graph: Graph) -> None:
    client = Peer(graph, "c", level=StatusLevel.WARNING)
    client.send(op="cancel_action_goal", action="/fib", id="nope")
    assert client.statuses()[0]["level"] == "warning"


def test_cancel_goal_service_cancels_every_goal_like_ros2(graph: Graph) -> None:
    """roslib's Action.cancelAllGoals calls <action>/_action/cancel_goal with empty args."""
    server, client, other = Peer(graph, "s"), Peer(graph, "c"), Peer(graph, "o")
    server.send(op="advertise_action", action="/fib", type=FIB)
    client.send(op="send_action_goal", action="/fib", action_type=FIB, id="a")
    other.send(op="send_action_goal", action="/fib", action_type=FIB, id="b")
    goal_ids = [g["id"] for g in server.received()]
    client.send(op="call_service", service="/fib/_action/cancel_goal", args={}, id="all")
    cancels = server.received()
    assert [(c["op"], c["id"]) for c in cancels] == [("cancel_action_goal", g) for g in goal_ids]
    [reply] = client.received()
    assert reply["result"] is True and reply["values"]["return_code"] == 0
    client.send(
        op="call_service",
        service="/fib/_action/cancel_goal",
        args={"goal_info": {"goal_id": {"uuid": list(range(1, 17))}}},
        id="one",
    )
    [unknown] = client.received()
    assert unknown["values"]["return_code"] == 2


def test_cancel_goal_service_goes_with_its_action(graph: Graph) -> None:
    server, client = Peer(graph, "s"), Peer(graph, "c")
    server.send(op="advertise_action", action="/fib", type=FIB)
    server.send(op="unadvertise_action", action="/fib")
    client.send(op="call_service", service="/fib/_action/cancel_goal", id=1)
    assert "does not exist" in str(client.received()[0]["values"])
