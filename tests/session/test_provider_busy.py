"""A provider whose send buffer is full of requests fails new callers; it is never cut.

Sessions on one graph, no sockets: the provider takes none of its frames, as a
provider that reads slower than it is called. Each request or goal carries
6 MB, so the third would take what waits for the provider over its 16 MiB
send buffer limit. Before, the third was queued all the same and the fourth
closed the provider's connection (``send buffer overflow``): its service or
action was gone. Now the third and fourth callers get ``provider busy`` at
once (a failed reply and an error status), the provider stays connected with
the two requests that fit, and once it has read them the next call goes
through (docs/limits.md).
"""

from __future__ import annotations

import logging

import pytest

from rwt_graph.graph import Graph
from tests.conftest import Peer

ARG = "x" * 6_000_000
SRV = "rosbridge_test_msgs/TestMultipleRequestFields"
ACTION = "rosbridge_test_msgs/TestMultipleGoalFields"
FIELDS = {"int_value": 1, "float_value": 0.5, "bool_value": True}


def test_a_full_service_provider_fails_the_caller_and_stays(
    graph: Graph, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="rwt")
    provider, caller = Peer(graph, "provider"), Peer(graph, "caller")
    provider.send(op="advertise_service", service="/store", type=SRV)
    for n in range(4):
        caller.send(op="call_service", service="/store", id=f"c{n}", args=FIELDS | {"string": ARG})
    replies = caller.received()
    assert [m["op"] for m in replies] == ["service_response", "status"] * 2
    assert [(m["id"], m["result"]) for m in replies[::2]] == [("c2", False), ("c3", False)]
    for reply, status in (replies[0:2], replies[2:4]):
        assert "service /store: provider busy" in str(reply["values"])
        assert "provider busy" in str(status["msg"]) and status["level"] == "error"
    # The log has one line for the episode (the callers decide how many refusals
    # there are), and no disconnection.
    busy = [r.getMessage() for r in caplog.records if "provider_busy" in r.getMessage()]
    assert len(busy) == 1 and "service=/store caller=caller" in busy[0], busy
    assert not [r for r in caplog.records if "overflow" in r.getMessage()]
    # The provider is connected and has the two requests that fit.
    assert not provider.session.closing
    requests = provider.received()
    assert [m["op"] for m in requests] == ["call_service", "call_service"]
    for request in requests:
        provider.send(op="service_response", service="/store", id=request["id"], result=True)
    assert [(m["id"], m["result"]) for m in caller.received()] == [("c0", True), ("c1", True)]
    # Having read them, it takes the next call.
    caller.send(op="call_service", service="/store", id="c3", args=FIELDS | {"string": ARG})
    [request] = provider.received()
    provider.send(op="service_response", service="/store", id=request["id"], result=True)
    assert [(m["id"], m["result"]) for m in caller.received()] == [("c3", True)]


def test_a_full_action_provider_aborts_the_goal_and_stays(graph: Graph) -> None:
    provider, caller = Peer(graph, "provider"), Peer(graph, "caller")
    provider.send(op="advertise_action", action="/work", type=ACTION)
    for n in range(4):
        caller.send(
            op="send_action_goal",
            action="/work",
            action_type=ACTION,
            id=f"g{n}",
            args=FIELDS | {"string": ARG},
        )
    replies = caller.received()
    assert [m["op"] for m in replies] == ["action_result", "status"] * 2
    assert [(m["id"], m["result"], m["status"]) for m in replies[::2]] == [
        ("g2", False, 6),  # aborted
        ("g3", False, 6),
    ]
    assert "action /work: provider busy" in str(replies[0]["values"])
    assert not provider.session.closing
    goals = provider.received()
    assert [m["op"] for m in goals] == ["send_action_goal", "send_action_goal"]
    for goal in goals:
        provider.send(op="action_result", action="/work", id=goal["id"], status=4, result=True)
    assert [(m["id"], m["result"]) for m in caller.received()] == [("g0", True), ("g1", True)]
