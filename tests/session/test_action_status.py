"""An action's status topic, and goals canceled from another connection (D35).

ROS 2 tools read ``<action>/_action/status`` (``action_msgs/msg/GoalStatusArray``)
to see what an action does; rosbridge_suite shares one goal table between its
connections, so a tool that opens a connection per call (ros-mcp) cancels a goal
sent on another one, also after that connection closed.
"""

from __future__ import annotations

import base64

import anyio
import pytest

from rwt_graph.action_status import FINISHED_KEPT, STATUS_SUFFIX
from rwt_graph.actions import MAX_LEFT_GOALS, GoalCanceledError, GoalContext
from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.access import AccessPolicy, parse_glob_list
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import running_handlers
from tests.conftest import Peer
from tests.session.test_gates import GatedPeer

FIB = "example_interfaces/action/Fibonacci"
STATUS = "action_msgs/msg/GoalStatusArray"
EXECUTING, CANCELING, SUCCEEDED, CANCELED = 2, 3, 4, 5


def _statuses(peer: Peer) -> list[list[int]]:
    """The status codes of each GoalStatusArray ``peer`` received, in order."""
    return [
        [goal["status"] for goal in m["msg"]["status_list"]]  # type: ignore[index]
        for m in peer.received()
        if m["op"] == "publish"
    ]


def _send_goal(peer: Peer, goal_id: str) -> None:
    peer.send(op="send_action_goal", action="/fib", action_type=FIB, args={"order": 9}, id=goal_id)


def test_status_is_published_at_each_transition_and_latched(graph: Graph) -> None:
    server, client, watcher = Peer(graph, "s"), Peer(graph, "c"), Peer(graph, "w")
    server.send(op="advertise_action", action="/fib", type=FIB)
    watcher.send(op="subscribe", topic="/fib" + STATUS_SUFFIX, type=STATUS)
    _send_goal(client, "g1")
    [goal] = server.received()
    client.send(op="cancel_action_goal", action="/fib", id="g1")
    server.send(op="action_result", action="/fib", id=goal["id"], status=5, result=True, values={})
    assert _statuses(watcher) == [[EXECUTING], [CANCELING], [CANCELED]]
    # a late subscriber gets the last list at once, as from a transient local publisher
    late = Peer(graph, "late")
    late.send(op="subscribe", topic="/fib/_action/status", type=STATUS)
    [message] = [m for m in late.received() if m["op"] == "publish"]
    [listed] = message["msg"]["status_list"]  # type: ignore[index]
    assert listed["status"] == CANCELED
    assert len(base64.b64decode(listed["goal_info"]["goal_id"]["uuid"])) == 16
    assert listed["goal_info"]["stamp"]["sec"] == int(graph.clock.wall())


@pytest.mark.anyio
async def test_an_in_process_action_publishes_its_status_and_a_caller_that_left_cancels(
    graph: Graph,
) -> None:
    """An in-process action server: its goals in the list, one outliving its caller."""
    started = anyio.Event()

    async def slow(goal: dict[str, object], context: GoalContext) -> dict[str, object]:
        started.set()
        while not context.cancel_requested:
            await anyio.sleep(0.01)
        raise GoalCanceledError

    graph.create_action_server("/fib", FIB, slow)
    watcher = Peer(graph, "w")
    watcher.send(op="subscribe", topic="/fib/_action/status", type=STATUS)
    async with running_handlers(graph) as tg:
        caller = Peer(graph, "c")
        _send_goal(caller, "goal_1")
        with anyio.fail_after(5):
            await started.wait()
        caller.session.close()  # the goal runs on (D35)
        Peer(graph, "later").send(op="cancel_action_goal", action="/fib", id="goal_1")
        seen: list[list[int]] = []
        with anyio.fail_after(5):
            while not seen or seen[-1] != [CANCELED]:
                seen += _statuses(watcher)
                await anyio.sleep(0.01)
        assert seen == [[EXECUTING], [CANCELING], [CANCELED]]
        tg.cancel_scope.cancel()


def test_the_status_list_keeps_the_last_finished_goals(graph: Graph) -> None:
    server, client, watcher = Peer(graph, "s"), Peer(graph, "c"), Peer(graph, "w")
    server.send(op="advertise_action", action="/fib", type=FIB)
    for n in range(FINISHED_KEPT + 5):
        _send_goal(client, f"g{n}")
        [goal] = server.received()
        server.send(op="action_result", action="/fib", id=goal["id"], result=True, values={})
    watcher.send(op="subscribe", topic="/fib/_action/status", type=STATUS)
    assert _statuses(watcher) == [[SUCCEEDED] * FINISHED_KEPT]


def test_another_connection_cancels_a_goal_by_its_id(graph: Graph) -> None:
    server, caller = Peer(graph, "s"), Peer(graph, "c")
    other = Peer(graph, "o", StatusLevel.WARNING)
    server.send(op="advertise_action", action="/fib", type=FIB)
    _send_goal(caller, "goal_42")
    [goal] = server.received()
    other.send(op="cancel_action_goal", action="/fib", id="goal_42")
    assert server.received() == [{"op": "cancel_action_goal", "id": goal["id"], "action": "/fib"}]
    assert other.statuses() == []
    other.send(op="cancel_action_goal", action="/fib", id="goal_43")
    [warning] = other.statuses()
    assert warning["level"] == "warning" and "no goal 'goal_43'" in str(warning["msg"])


def test_a_goal_outlives_its_caller_and_is_canceled_later(graph: Graph) -> None:
    server, caller = Peer(graph, "s"), Peer(graph, "c")
    server.send(op="advertise_action", action="/fib", type=FIB)
    _send_goal(caller, "goal_1")
    [goal] = server.received()
    caller.session.close()
    assert server.received() == []  # not canceled: it runs on, as on rosbridge_suite
    later = Peer(graph, "later")
    later.send(op="cancel_action_goal", action="/fib", id="goal_1")
    assert server.received() == [{"op": "cancel_action_goal", "id": goal["id"], "action": "/fib"}]
    server.send(op="action_result", action="/fib", id=goal["id"], status=5, result=True, values={})
    assert server.statuses() == []  # its result goes nowhere, without complaint
    assert not graph.actions.entries["/fib"].goals


def test_goals_left_behind_are_bounded(graph: Graph) -> None:
    server = Peer(graph, "s")
    server.send(op="advertise_action", action="/fib", type=FIB)
    for n in range(MAX_LEFT_GOALS + 3):
        caller = Peer(graph, f"c{n}")
        _send_goal(caller, "g")
        caller.session.close()
    cancels = [m for m in server.received() if m["op"] == "cancel_action_goal"]
    assert [c["id"] for c in cancels] == [f"action_goal:/fib:{n}" for n in (1, 2, 3)]
    assert len(graph.actions.entries["/fib"].goals) == MAX_LEFT_GOALS + 3  # until they end


def test_the_access_rules_decide_who_may_cancel(graph: Graph) -> None:
    server, caller = Peer(graph, "s"), Peer(graph, "c")
    server.send(op="advertise_action", action="/fib", type=FIB)
    _send_goal(caller, "g")
    server.received()
    policy = AccessPolicy(actions=parse_glob_list("[/public/*]"))
    denied = GatedPeer(graph, "d", SessionConfig(access=policy))
    denied.send(op="cancel_action_goal", action="/fib", id="g")
    assert server.received() == []
    assert any("not allowed" in str(m.get("msg")) for m in denied.received())
