"""A Foxglove client learns the graph from its change feed, not by walking it.

An idle client sets no timer and reads nothing of the graph; a client new to
thousands of topics gets them in bounded advertisements, one waiting at a time;
churning the connection-graph subscription without reading holds one update and
builds the whole graph once. Sans-IO: the session is driven by hand, taking its
frames only when a test says the client read.
"""

from __future__ import annotations

import json

import pytest

from rwt_foxglove import FoxgloveSession, conngraph
from rwt_foxglove.limits import ADVERTISE_BATCH_CHANNELS
from rwt_graph.graph import Graph
from tests.foxglove.sansio import Client

TOPICS = 5_000


def _ops(frames: list[object], name: str) -> list[dict[str, object]]:
    ops = [json.loads(frame.data) for frame in frames if not frame.binary]  # type: ignore[attr-defined]
    return [op for op in ops if op["op"] == name]


def _big_graph(topics: int) -> Graph:
    graph = Graph()
    for n in range(topics):
        graph.create_publisher(f"/t{n}", "std_msgs/msg/String", node="/big")
    return graph


def test_an_idle_client_sets_no_timer_and_reads_nothing_of_the_graph(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    graph = _big_graph(2_000)
    client = Client(graph)
    assert len(client.take_ops("advertise")) > 2_000 // ADVERTISE_BATCH_CHANNELS
    walks: list[int] = []
    snapshot = graph.port.feed.snapshot
    monkeypatch.setattr(graph.port.feed, "snapshot", lambda: walks.append(1) or snapshot())
    assert client.session.get_timer() is None  # nothing to do: no wake-up
    graph.create_publisher("/new", "std_msgs/msg/String")
    assert client.session.get_timer() == client.now  # the change, announced at once
    client.drain()
    assert [c["topic"] for op in client.take_ops("advertise") for c in op["channels"]] == ["/new"]
    assert client.session.get_timer() is None
    assert walks == []


def test_a_new_client_of_thousands_of_topics_gets_bounded_batches_one_waiting_at_a_time() -> None:
    graph = _big_graph(TOPICS)
    session = FoxgloveSession(graph.port, "foxglove:test#1", session_id="s1")
    advertised: set[str] = set()
    for _ in range(3):  # a client that never reads: one batch waits, no other is made
        session.handle_timer(0.0)
    assert session.queued_messages <= 3  # serverInfo, one advertise, one advertiseServices
    while True:
        frames = session.frames_to_send()  # the client read all: the next batch may come
        session.handle_timer(0.0)
        batches = _ops(frames, "advertise")
        if not batches:
            break
        assert len(batches) == 1 and len(batches[0]["channels"]) <= ADVERTISE_BATCH_CHANNELS  # type: ignore[arg-type]
        advertised.update(c["topic"] for c in batches[0]["channels"])  # type: ignore[attr-defined]
    assert {f"/t{n}" for n in range(TOPICS)} <= advertised
    assert session.get_timer() is None


def test_connection_graph_churn_without_reading_holds_one_update_and_walks_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    graph = _big_graph(2_000)
    session = FoxgloveSession(graph.port, "foxglove:test#1", session_id="s1")
    views: list[int] = []
    view_of = conngraph.view_of
    monkeypatch.setattr(
        conngraph, "view_of", lambda *args: views.append(len(args)) or view_of(*args)
    )
    session.receive_frame(b'{"op": "subscribeConnectionGraph"}', 0.0, binary=False)
    held = session.stats.queued_bytes
    for _ in range(4_000):  # never reads: each subscribe used to queue the whole graph
        session.receive_frame(b'{"op": "unsubscribeConnectionGraph"}', 0.0, binary=False)
        session.receive_frame(b'{"op": "subscribeConnectionGraph"}', 0.0, binary=False)
    session.handle_timer(0.0)
    assert session.stats.queued_bytes == held
    assert views == [1]  # the whole graph once: no walk per subscription
    frames = session.frames_to_send()
    (update,) = _ops(frames, "connectionGraphUpdate")
    assert len(update["publishedTopics"]) >= 2_000  # type: ignore[arg-type]
    graph.create_publisher("/late", "std_msgs/msg/String", node="/late")  # then the change only
    session.handle_timer(0.0)
    (change,) = _ops(session.frames_to_send(), "connectionGraphUpdate")
    assert change["publishedTopics"] == [{"name": "/late", "publisherIds": ["/late"]}]
    assert views == [1, 3]  # the changed name only


def test_a_client_that_never_reads_holds_one_advertisement_under_topic_churn() -> None:
    graph = Graph()
    session = FoxgloveSession(graph.port, "foxglove:test#1", session_id="s1")
    session.handle_timer(0.0)
    session.frames_to_send()  # up to date, then it reads no more
    for _ in range(2_000):  # a topic advertised and withdrawn, over and over
        graph.port.advertise("peer", "/churn", "std_msgs/msg/String")
        session.handle_timer(0.0)
        graph.port.unadvertise("peer", "/churn")
        session.handle_timer(0.0)
    assert session.queued_messages <= 2  # was one frame per change (4,001 held)
    told: list[str] = []
    for _ in range(2):  # it reads again: what it holds, then what changed since
        frames = session.frames_to_send()
        told += [op["op"] for op in map(json.loads, (f.data for f in frames))]
        session.handle_timer(0.0)
    assert [op for op in told if "advertise" in op] == ["advertise", "unadvertise"]
