"""A participant's release and disconnect cost what it holds, not the size of the graph.

A Zenoh peer whose thousands of publisher tokens vanish at once makes the link
release thousands of participants; each client disconnect releases one. Walking
every topic, service and action of the graph per release made that quadratic
(docs/limits.md, "Zenoh peers: what they are trusted with"). These tests build a
large graph, count the walks over its whole tables while one participant is
released, and check that exactly that participant's registrations went.
"""

from __future__ import annotations

from _collections_abc import dict_items, dict_keys, dict_values
from collections.abc import Iterator
from typing import Any

from rwt_graph.graph import Graph
from rwt_graph.parameters.store import Parameters
from rwt_protocol.ops import (
    CallService,
    CancelActionGoal,
    SendActionGoal,
)
from rwt_protocol.ports import MessageEvent

STRING = "std_msgs/msg/String"
ADD = "example_interfaces/srv/AddTwoInts"
FIB = "example_interfaces/action/Fibonacci"
OTHERS = 2000


class CountingDict(dict[Any, Any]):
    """A dict that counts the walks over all of it (iteration, keys, values, items)."""

    walks = 0

    def __iter__(self) -> Iterator[Any]:
        CountingDict.walks += 1
        return super().__iter__()

    def keys(self) -> dict_keys[Any, Any]:
        CountingDict.walks += 1
        return super().keys()

    def values(self) -> dict_values[Any, Any]:
        CountingDict.walks += 1
        return super().values()

    def items(self) -> dict_items[Any, Any]:
        CountingDict.walks += 1
        return super().items()


class Sink:
    def __init__(self) -> None:
        self.messages: list[MessageEvent] = []

    def on_message(self, event: MessageEvent) -> None:
        self.messages.append(event)


class Provider:
    """A client provider of services and actions that never answers by itself."""

    def __init__(self) -> None:
        self.requests: list[str] = []
        self.cancels: list[str] = []

    def on_service_request(self, request: CallService) -> None:
        self.requests.append(str(request.id))

    def on_service_lost(self, service: str, reason: str) -> None:
        pass

    def on_action_goal(self, goal: SendActionGoal) -> None:
        self.requests.append(str(goal.id))

    def on_action_cancel(self, cancel: CancelActionGoal) -> None:
        self.cancels.append(str(cancel.id))

    def on_action_lost(self, action: str, reason: str) -> None:
        pass


def counted(graph: Graph) -> None:
    """Make the graph's whole-table walks countable."""
    graph.port.topics = CountingDict(graph.port.topics)
    graph.services.entries = CountingDict(graph.services.entries)
    graph.actions.entries = CountingDict(graph.actions.entries)


def large_graph() -> tuple[Graph, list[tuple[object, ...]]]:
    """``OTHERS`` clients, each publishing, subscribing, serving and calling one another."""
    graph = Graph()
    replies: list[tuple[object, ...]] = []
    provider = Provider()
    for n in range(OTHERS):
        client = f"other{n}"
        graph.port.advertise(client, f"/pub{n}", STRING)
        graph.port.subscribe(client, f"/sub{n}", STRING, Sink())
        graph.port.advertise_service(client, f"/srv{n}", ADD, provider)
        graph.port.advertise_action(client, f"/act{n}", FIB, provider)
    for n in range(OTHERS):  # each calls its neighbour's service and action
        peer = (n + 1) % OTHERS
        graph.port.call_service(f"other{n}", f"/srv{peer}", {}, lambda *r: replies.append(r))
        graph.port.send_action_goal(
            f"other{n}",
            f"/act{peer}",
            {},
            lambda *r: replies.append(r),
        )
    return graph, replies


def test_releasing_one_client_walks_no_table_and_drops_only_what_it_held() -> None:
    graph, replies = large_graph()
    provider = Provider()
    other_provider = graph.actions.entries["/act6"].provider
    assert isinstance(other_provider, Provider)
    sink = Sink()
    graph.port.advertise("holder", "/pub0", STRING, latch=True)
    graph.port.subscribe("holder", "/sub1", STRING, sink)
    graph.port.advertise_service("holder", "/mine", ADD, provider)
    graph.port.advertise_action("holder", "/my_action", FIB, provider)
    graph.port.call_service("holder", "/srv5", {}, lambda *r: replies.append(("holder", *r)))
    graph.port.send_action_goal(
        "holder",
        "/act6",
        {},
        lambda *r: replies.append(("holder", *r)),
    )
    answers: list[tuple[object, ...]] = []
    graph.port.call_service("other7", "/mine", {}, lambda *r: answers.append(r))
    counted(graph)
    CountingDict.walks = 0

    graph.port.release("holder")

    assert CountingDict.walks == 0
    assert "holder" not in graph.port.topics["/pub0"].publishers
    assert "holder" not in graph.port.topics["/sub1"].subscribers
    assert "/mine" not in graph.services.entries
    assert "/my_action" not in graph.actions.entries
    assert answers == [(False, "service /mine is gone: its provider disconnected")]
    # its own call and goal are forgotten; the neighbours' are not
    assert [c.caller for c in graph.services.entries["/srv5"].pending.values()] == ["other4"]
    goals = {g.caller: g for g in graph.actions.entries["/act6"].goals.values()}
    assert goals["holder"].finished  # the provider was asked to cancel it
    assert other_provider.cancels == [goals["holder"].goal_id]
    assert not goals["other5"].finished
    assert all(reply[0] != "holder" for reply in replies)
    # everything else stays: every other client's topics, services and actions
    assert len(graph.port.topics) == 3 * OTHERS  # each action has its status topic
    assert len(graph.services.entries) == 2 * OTHERS  # each action has its cancel service
    assert len(graph.actions.entries) == OTHERS


def test_releasing_every_client_one_by_one_leaves_an_empty_graph() -> None:
    graph, replies = large_graph()
    counted(graph)
    CountingDict.walks = 0

    for n in range(OTHERS):
        graph.port.release(f"other{n}")

    assert CountingDict.walks == 0
    assert not graph.port.topics
    assert not graph.services.entries
    assert not graph.actions.entries
    assert not graph.nodes.names()
    # each call and goal was answered once, by its provider leaving or forgotten with its caller
    assert len(replies) <= 2 * OTHERS


def test_unadvertising_then_releasing_forgets_the_topic_once() -> None:
    graph = Graph()
    graph.port.advertise("a", "/t", STRING)
    graph.port.unadvertise("a", "/t")
    graph.port.subscribe("b", "/t", STRING, Sink())
    graph.port.advertise("a", "/u", STRING)
    counted(graph)

    graph.port.release("a")

    assert CountingDict.walks == 0
    assert list(graph.port.topics) == ["/t"]
    assert "a" not in graph.port.topics["/t"].publishers


def test_a_node_lists_its_participants_without_walking_every_participant() -> None:
    graph = Graph()
    for n in range(OTHERS):
        graph.nodes.bind(f"p{n}", f"/node{n % 10}")
    graph.nodes.forget("p0")
    graph.nodes.bind("p1", "/elsewhere")
    graph.nodes._names = CountingDict(graph.nodes._names)
    CountingDict.walks = 0

    assert graph.nodes.clients_of("/node0") == {f"p{n}" for n in range(10, OTHERS, 10)}
    assert graph.nodes.clients_of("/elsewhere") == {"p1"}
    assert "/node1" in graph.nodes.names()
    assert graph.nodes.clients_of("/node1") == {f"p{n}" for n in range(11, OTHERS, 10)}
    assert CountingDict.walks == 0


def test_a_new_parameter_checks_room_without_walking_every_node() -> None:
    params = Parameters(Graph().registry.dialect, max_params=3)
    params.set("/a:x", 1)
    params.set("/b:x", 2)
    params.delete("/a:x")
    params._nodes = CountingDict(params._nodes)
    CountingDict.walks = 0

    params.set("/c:x", 3)
    params.set("/c:x", 4)  # a change, not a new parameter

    assert CountingDict.walks == 0
    assert params.get("/c:x") == 4
