"""The graph's change feed (rwt_graph.feed): every entity a participant gains or loses, once.

What a consumer of the feed holds (a snapshot, then every change) must be what a
rescan of the graph's tables finds, whatever the graph went through: that is
what lets Foxglove clients, links and rosapi follow the graph without sweeping it.
"""

from __future__ import annotations

import logging

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rwt_graph.feed import ChangeFeed, EntityKind, GraphChange
from rwt_graph.graph import Graph
from rwt_graph.link import LinkRules
from rwt_graph.mirror import Mirror, RemoteEntity, RemoteKind
from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.errors import RwtError
from rwt_protocol.ops import CallService, CancelActionGoal, SendActionGoal
from rwt_protocol.ports import MessageEvent

STRING = "std_msgs/msg/String"
INT32 = "std_msgs/msg/Int32"
SET_BOOL = "std_srvs/srv/SetBool"
TRIGGER = "std_srvs/srv/Trigger"
FIB = "example_interfaces/action/Fibonacci"
CANCEL = "action_msgs/srv/CancelGoal"

PUB, SUB = EntityKind.PUBLISHER, EntityKind.SUBSCRIPTION
SRV, ACT = EntityKind.SERVICE, EntityKind.ACTION

State = dict[tuple[EntityKind, str, str], tuple[str, bool, str | None]]


class _Sink:
    def on_message(self, event: MessageEvent) -> None:
        pass


class _Provider:
    """A client session's provider, for services and actions alike."""

    def on_service_request(self, request: CallService) -> None:
        pass

    def on_service_lost(self, service: str, reason: str) -> None:
        pass

    def on_action_goal(self, goal: SendActionGoal) -> None:
        pass

    def on_action_cancel(self, cancel: CancelActionGoal) -> None:
        pass

    def on_action_lost(self, action: str, reason: str) -> None:
        pass


class _Heard:
    """A listener keeping every change it hears."""

    def __init__(self, feed: ChangeFeed) -> None:
        self.changes: list[GraphChange] = []
        self.stop = feed.listen(self.changes.append)

    def told(self) -> list[tuple[str, EntityKind, str, str]]:
        """Each change as (added or removed, kind, name, client), in order."""
        return [("+" if c.added else "-", c.kind, c.name, c.client) for c in self.changes]

    def take(self) -> list[tuple[str, EntityKind, str, str]]:
        told = self.told()
        self.changes.clear()
        return told


def rescan(graph: Graph) -> State:
    """The entities of the graph as its tables hold them (what the feed saves a consumer)."""
    nodes = graph.nodes
    state: State = {}
    for name, topic in graph.topics.items():
        for client, latched in topic.publishers.items():
            state[(PUB, name, client)] = (topic.msgtype.name, latched, nodes.node_of(client))
        for client in topic.subscribers:
            state[(SUB, name, client)] = (topic.msgtype.name, False, nodes.node_of(client))
    for name, service in graph.services.entries.items():
        state[(SRV, name, service.owner)] = (
            service.srvtype.name,
            False,
            nodes.node_of(service.owner),
        )
    for name, action in graph.actions.entries.items():
        state[(ACT, name, action.owner)] = (
            action.actiontype.name,
            False,
            nodes.node_of(action.owner),
        )
    return state


class _Follower:
    """A consumer of the feed: a snapshot, then every change applied to it."""

    def __init__(self, feed: ChangeFeed) -> None:
        self.version, entities = feed.snapshot()
        self.state: State = {}
        for change in entities:
            self.apply(change)
        feed.listen(self.heard)

    def heard(self, change: GraphChange) -> None:
        assert change.version == self.version + 1  # each once, in order
        self.version = change.version
        self.apply(change)

    def apply(self, change: GraphChange) -> None:
        key = (change.kind, change.name, change.client)
        if change.added:
            assert key not in self.state
            self.state[key] = (change.type_name, change.latched, change.node)
        else:
            assert self.state.pop(key) == (change.type_name, change.latched, change.node)


def test_topics_announce_each_publisher_and_subscription_once_with_versions() -> None:
    graph = Graph()
    port = graph.port
    graph.nodes.attach("ws:1")
    heard = _Heard(port.feed)
    port.advertise("ws:1", "/chatter", STRING)
    port.advertise("ws:1", "chatter", STRING)  # the same publisher again: no change
    port.subscribe("ws:2", "/chatter", None, _Sink())
    port.subscribe("ws:2", "/chatter", STRING, _Sink())  # its sink replaced: no change
    port.publish("ws:3", "/chatter", {"data": "a"})  # publishing without advertising (REF §2.3)
    port.publish("ws:3", "/chatter", {"data": "b"})
    port.unadvertise("ws:1", "/chatter")
    port.unsubscribe("ws:2", "/chatter")
    port.release("ws:3")
    assert heard.told() == [
        ("+", PUB, "/chatter", "ws:1"),
        ("+", SUB, "/chatter", "ws:2"),
        ("+", PUB, "/chatter", "ws:3"),
        ("-", PUB, "/chatter", "ws:1"),
        ("-", SUB, "/chatter", "ws:2"),
        ("-", PUB, "/chatter", "ws:3"),
    ]
    assert [c.version for c in heard.changes] == [1, 2, 3, 4, 5, 6]
    assert port.feed.version == 6
    first = heard.changes[0]
    assert (first.type_name, first.latched, first.node) == (STRING, False, "/rwt_client_1")
    assert heard.changes[1].node is not None  # a participant never seen gets its client node
    assert port.feed.snapshot() == (6, [])


def test_a_publisher_that_starts_to_latch_and_a_retyped_topic_are_removal_then_addition() -> None:
    graph = Graph()
    port = graph.port
    heard = _Heard(port.feed)
    port.advertise("ws:1", "/map", STRING)
    port.advertise("ws:1", "/map", STRING, latch=True)
    port.advertise("ws:1", "/map", STRING)  # a latching publisher stays latched
    port.unadvertise("ws:1", "/map")
    port.advertise("ws:2", "/map", INT32)  # the topic made again with another type
    assert [(c.added, c.type_name, c.latched) for c in heard.changes] == [
        (True, STRING, False),
        (False, STRING, False),
        (True, STRING, True),
        (False, STRING, True),
        (True, INT32, False),
    ]


def test_services_and_actions_announce_their_providers_and_d15_replacements() -> None:
    graph = Graph()
    port = graph.port
    heard = _Heard(port.feed)
    provider = _Provider()
    port.advertise_service("ws:1", "/enable", SET_BOOL, provider)
    port.advertise_service("ws:2", "enable", SET_BOOL, provider)  # newest wins (D15)
    port.unadvertise_service("ws:2", "/enable")
    assert heard.take() == [
        ("+", SRV, "/enable", "ws:1"),
        ("-", SRV, "/enable", "ws:1"),
        ("+", SRV, "/enable", "ws:2"),
        ("-", SRV, "/enable", "ws:2"),
    ]
    port.advertise_action("ws:1", "/fib", FIB, provider)
    port.advertise_action("ws:2", "/fib", FIB, provider)
    port.release("ws:2")
    assert heard.take() == [
        ("+", ACT, "/fib", "ws:1"),
        ("+", SRV, "/fib/_action/cancel_goal", "ws:1"),
        ("+", PUB, "/fib/_action/status", "ws:1"),  # the graph publishes its status
        ("-", ACT, "/fib", "ws:1"),
        ("+", ACT, "/fib", "ws:2"),
        ("-", PUB, "/fib/_action/status", "ws:1"),  # the status goes with the action
        ("-", SRV, "/fib/_action/cancel_goal", "ws:1"),
        ("+", SRV, "/fib/_action/cancel_goal", "ws:2"),
        ("+", PUB, "/fib/_action/status", "ws:2"),
        ("-", PUB, "/fib/_action/status", "ws:2"),
        ("-", SRV, "/fib/_action/cancel_goal", "ws:2"),
        ("-", ACT, "/fib", "ws:2"),
    ]
    assert {(c.kind, c.type_name) for c in heard.changes} <= {(SRV, CANCEL), (ACT, FIB)}


def test_in_process_handles_announce_with_their_node() -> None:
    graph = Graph()
    heard = _Heard(graph.port.feed)
    publisher = graph.create_publisher("/odom", STRING, node="/robot")
    service = graph.create_service("/reset", TRIGGER, lambda request: {}, node="/robot")
    publisher.close()
    service.close()
    assert [(c.added, c.kind, c.node) for c in heard.changes] == [
        (True, PUB, "/robot"),
        (True, SRV, "/robot"),
        (False, PUB, "/robot"),
        (False, SRV, "/robot"),
    ]


def test_what_a_link_mirrors_in_is_announced_in_its_remote_node() -> None:
    graph = Graph()
    heard = _Heard(graph.port.feed)
    side = _Side()
    mirror = Mirror(graph, LinkRules("link:"), side, EpisodeLog(logging.getLogger("t")), event="t")
    mirror.add("link:p", RemoteEntity(RemoteKind.PUBLISHER, "/far", "/odom", STRING, latched=True))
    mirror.add("link:s", RemoteEntity(RemoteKind.SERVICE, "/far", "/enable", SET_BOOL))
    mirror.close()
    assert [(c.added, c.kind, c.client, c.node, c.latched) for c in heard.changes] == [
        (True, PUB, "link:p", "/far", True),
        (True, SRV, "link:s", "/far", False),
        (False, PUB, "link:p", "/far", True),
        (False, SRV, "link:s", "/far", False),
    ]


class _Side:
    def check_endpoint(self, entity: RemoteEntity) -> None:
        pass

    def service_provider(self, client: str, entity: RemoteEntity) -> _Provider:
        return _Provider()

    def action_provider(self, client: str, entity: RemoteEntity) -> _Provider:
        return _Provider()

    def released(self, client: str, entity: RemoteEntity, provider: object) -> None:
        pass


def test_a_node_bound_anew_re_announces_its_participants_entities() -> None:
    graph = Graph()
    port = graph.port
    graph.nodes.bind("local:9", "/first")
    port.advertise("local:9", "/a", STRING)
    port.subscribe("local:9", "/b", STRING, _Sink())
    heard = _Heard(port.feed)
    graph.nodes.bind("local:9", "/first")  # the same node: nothing
    graph.nodes.bind("local:9", "/second")
    assert [(c.added, c.name, c.node) for c in heard.changes] == [
        (False, "/a", "/first"),
        (True, "/a", "/second"),
        (False, "/b", "/first"),
        (True, "/b", "/second"),
    ]
    assert port.feed.get(PUB, "/a", "local:9") == heard.changes[1]


def test_publishing_costs_the_feed_nothing() -> None:
    graph = Graph()
    heard = _Heard(graph.port.feed)
    publisher = graph.create_publisher("/fast", STRING)
    for n in range(100):
        publisher.publish({"data": str(n)})
        graph.port.publish("ws:1", "/fast", {"data": str(n)})
    assert len(heard.changes) == 2  # the two publishers, not their messages


def test_a_listener_that_raises_is_contained_and_logged_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    graph = Graph()

    def broken(change: GraphChange) -> None:
        raise RuntimeError("a consumer's bug")

    graph.port.feed.listen(broken)
    heard = _Heard(graph.port.feed)
    with caplog.at_level(logging.ERROR, logger="rwt.graph"):
        graph.port.advertise("ws:1", "/a", STRING)
        graph.port.advertise("ws:1", "/b", STRING)
    assert heard.told() == [("+", PUB, "/a", "ws:1"), ("+", PUB, "/b", "ws:1")]
    assert sorted(graph.topics) == ["/a", "/b"]  # the graph's calls went through
    failures = [r for r in caplog.records if "feed_listener_failed" in r.getMessage()]
    assert len(failures) == 1  # once per episode, its repeats counted


def test_a_change_made_by_a_listener_waits_until_every_listener_heard_the_current_one() -> None:
    graph = Graph()
    port = graph.port
    first: list[tuple[int, str]] = []
    second: list[tuple[int, str]] = []

    def echo(change: GraphChange) -> None:  # reacts to /a by advertising /echo
        first.append((change.version, change.name))
        if change.name == "/a" and change.added:
            port.advertise("ws:echo", "/echo", STRING)
            assert "/echo" in graph.topics  # the graph has it at once

    port.feed.listen(echo)
    port.feed.listen(lambda change: second.append((change.version, change.name)))
    port.advertise("ws:1", "/a", STRING)
    assert first == second == [(1, "/a"), (2, "/echo")]


def test_a_follower_that_stops_hears_nothing_more() -> None:
    graph = Graph()
    heard = _Heard(graph.port.feed)
    graph.port.advertise("ws:1", "/a", STRING)
    heard.stop()
    graph.port.advertise("ws:1", "/b", STRING)
    assert heard.told() == [("+", PUB, "/a", "ws:1")]


CLIENTS = ("ws:1", "ws:2", "link:9", "local:7")
TOPICS = ("/a", "b", "/c")
SERVICES = ("/s", "/t")

operations = st.one_of(
    st.tuples(
        st.just("advertise"),
        st.sampled_from(CLIENTS),
        st.sampled_from(TOPICS),
        st.sampled_from((STRING, INT32)),
        st.booleans(),
    ),
    st.tuples(st.just("unadvertise"), st.sampled_from(CLIENTS), st.sampled_from(TOPICS)),
    st.tuples(st.just("publish"), st.sampled_from(CLIENTS), st.sampled_from(TOPICS)),
    st.tuples(
        st.just("subscribe"),
        st.sampled_from(CLIENTS),
        st.sampled_from(TOPICS),
        st.sampled_from((STRING, INT32, None)),
    ),
    st.tuples(st.just("unsubscribe"), st.sampled_from(CLIENTS), st.sampled_from(TOPICS)),
    st.tuples(
        st.just("advertise_service"),
        st.sampled_from(CLIENTS),
        st.sampled_from(SERVICES),
        st.sampled_from((SET_BOOL, TRIGGER)),
    ),
    st.tuples(st.just("unadvertise_service"), st.sampled_from(CLIENTS), st.sampled_from(SERVICES)),
    st.tuples(st.just("advertise_action"), st.sampled_from(CLIENTS)),
    st.tuples(st.just("unadvertise_action"), st.sampled_from(CLIENTS)),
    st.tuples(st.just("release"), st.sampled_from(CLIENTS)),
    st.tuples(st.just("bind"), st.sampled_from(CLIENTS), st.sampled_from(("/n1", "/n2"))),
    st.tuples(st.just("forget"), st.sampled_from(CLIENTS)),
)


def run(graph: Graph, operation: tuple[object, ...]) -> None:
    """One graph operation; a refused one (a type clash, not the owner) changes nothing."""
    port, provider = graph.port, _Provider()
    name, client, *args = operation
    assert isinstance(client, str)
    try:
        if name == "advertise":
            port.advertise(client, str(args[0]), str(args[1]), latch=bool(args[2]))
        elif name == "publish":
            port.publish(client, str(args[0]), {})
        elif name == "subscribe":
            type_name = None if args[1] is None else str(args[1])
            port.subscribe(client, str(args[0]), type_name, _Sink())
        elif name in ("unadvertise", "unsubscribe", "unadvertise_service"):
            getattr(port, name)(client, args[0])
        elif name == "advertise_service":
            port.advertise_service(client, str(args[0]), str(args[1]), provider)
        elif name == "advertise_action":
            port.advertise_action(client, "/fib", FIB, provider)
        elif name == "unadvertise_action":
            port.unadvertise_action(client, "/fib")
        elif name == "release":
            port.release(client)
        elif name == "bind":
            graph.nodes.bind(client, str(args[0]))
        else:
            graph.nodes.forget(client)
    except RwtError:
        pass


@settings(max_examples=150, deadline=None)
@given(st.lists(operations, max_size=40), st.integers(min_value=0, max_value=40))
def test_a_snapshot_and_the_changes_after_it_equal_a_rescan(
    sequence: list[tuple[object, ...]], join_at: int
) -> None:
    """Whatever the graph went through, a follower holds what a rescan of its tables finds."""
    graph = Graph()
    early = _Follower(graph.port.feed)
    late: _Follower | None = None
    for index, operation in enumerate(sequence):
        if index == join_at:
            late = _Follower(graph.port.feed)
        run(graph, operation)
        assert early.state == rescan(graph)
    late = late or _Follower(graph.port.feed)
    assert late.state == early.state == rescan(graph)
    version, entities = graph.port.feed.snapshot()
    assert version == early.version == graph.port.feed.version
    assert [c.version for c in entities] == sorted(c.version for c in entities)
