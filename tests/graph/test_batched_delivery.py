"""Batched delivery: a turn's serialized publishes reach queueing subscribers at its end.

While a server lends the graph its loop (``GraphCore.serving`` with ``soon``),
serialized messages published on a topic whose every subscriber takes batches
(``BatchSink``: a Foxglove client) are delivered when the loop's turn ends, a
topic's run in one call per sink. The rule (docs/embedding.md, "Batched
delivery"): every sink sees the graph's messages in publish order; any other
delivery, subscribe or unsubscribe delivers the batch first; latched messages,
topics with another kind of subscriber and graphs with taps are delivered at
once; after a batch of one message the next ``SOLO_AFTER_ONE`` go at once; a
batch that reaches ``BATCH_MAX_MESSAGES`` or ``BATCH_MAX_BYTES`` is delivered at
once (a publisher that never yields holds no more in the graph); a batch still
open when serving ends is delivered then. Off
(``RWT_NO_SHORTCUTS=batched-delivery``) or without a loop, everything is
delivered as it is published.
"""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import anyio
import anyio.lowlevel
import pytest
from tests.support.shortcuts import switch_off

from rwt_graph.core import BATCH_MAX_BYTES, BATCH_MAX_MESSAGES, SOLO_AFTER_ONE
from rwt_graph.graph import Graph
from rwt_graph.local import LocalPublisher
from rwt_protocol.errors import GraphError
from rwt_protocol.ports import MessageEvent

pytestmark = [pytest.mark.anyio, pytest.mark.uvloop_too]


@pytest.fixture(autouse=True)
def batching_on(monkeypatch: pytest.MonkeyPatch) -> None:
    """The shortcut on, whatever ``RWT_NO_SHORTCUTS`` says (one test switches it off)."""
    switch_off(monkeypatch, None)


STRING = "std_msgs/msg/String"


def cdr(text: str) -> bytes:
    """``std_msgs/msg/String`` as rclpy serializes it (little-endian CDR)."""
    data = text.encode() + b"\0"
    return b"\0\1\0\0" + len(data).to_bytes(4, "little") + data + b"\0" * (-len(data) % 4)


class Log:
    """What the sinks of a test got, in order: (sink, text, calls it came in)."""

    def __init__(self) -> None:
        self.entries: list[tuple[str, str]] = []
        self.batches: list[tuple[str, int]] = []  # (sink, messages in the call)

    def texts(self, sink: str | None = None) -> list[str]:
        return [text for name, text in self.entries if sink is None or name == sink]


def text_of(event: MessageEvent) -> str:
    data = event.msg["data"]
    assert isinstance(data, str)
    return data


class Queueing:
    """A sink that takes batches, as a Foxglove client's does."""

    def __init__(self, log: Log, name: str) -> None:
        self.log, self.name = log, name

    def on_message(self, event: MessageEvent) -> None:
        self.on_messages([event])

    def on_messages(self, events: list[MessageEvent]) -> None:
        self.log.batches.append((self.name, len(events)))
        self.log.entries += [(self.name, text_of(event)) for event in events]


class Plain:
    """A sink that takes one message at a time (a Python callback's, a rosbridge client's)."""

    def __init__(self, log: Log, name: str) -> None:
        self.log, self.name = log, name

    def on_message(self, event: MessageEvent) -> None:
        self.log.batches.append((self.name, 1))
        self.log.entries.append((self.name, text_of(event)))


def subscribe(graph: Graph, client: str, topic: str, sink: object) -> None:
    graph.port.subscribe(client, topic, STRING, sink)  # type: ignore[arg-type]


def one_topic() -> tuple[Graph, Log, LocalPublisher]:
    """A graph whose ``/a`` has a publisher and one queueing subscriber, ``fox``."""
    graph, log = Graph(), Log()
    subscribe(graph, "fox", "/a", Queueing(log, "fox"))
    return graph, log, graph.create_publisher("/a", STRING)


@contextmanager
def served(graph: Graph) -> Iterator[None]:
    """The graph as a server serves it: async jobs unused, the loop's ``call_soon`` lent."""

    def spawn(job: Callable[[], object]) -> Callable[[], None]:
        raise AssertionError("no async job here")

    with graph.port.serving(spawn, asyncio.get_running_loop().call_soon):  # type: ignore[arg-type]
        yield


async def test_a_turns_burst_reaches_a_queueing_sink_at_its_end_in_one_call() -> None:
    graph, log, publisher = one_topic()
    with served(graph):
        for i in range(5):
            publisher.publish(cdr(f"a{i}"))
        assert log.entries == []  # not yet: the turn goes on
        await anyio.lowlevel.checkpoint()
        assert log.texts() == [f"a{i}" for i in range(5)]
        assert log.batches == [("fox", 5)]


async def test_runs_of_several_topics_keep_the_publish_order_for_a_client_of_both() -> None:
    graph, log = Graph(), Log()
    subscribe(graph, "fox-a", "/a", Queueing(log, "fox"))
    subscribe(graph, "fox-b", "/b", Queueing(log, "fox"))
    a, b = graph.create_publisher("/a", STRING), graph.create_publisher("/b", STRING)
    order = ["a0", "a1", "b0", "a2", "b1", "b2", "b3"]
    with served(graph):
        for text in order:
            (a if text[0] == "a" else b).publish(cdr(text))
        await anyio.lowlevel.checkpoint()
    assert log.texts() == order
    assert [size for _, size in log.batches] == [2, 1, 1, 3]  # one call per run


async def test_another_delivery_in_the_turn_delivers_the_batch_first() -> None:
    graph, log = Graph(), Log()
    subscribe(graph, "fox", "/a", Queueing(log, "fox"))
    subscribe(graph, "ros", "/c", Plain(log, "ros"))
    a, c = graph.create_publisher("/a", STRING), graph.create_publisher("/c", STRING)
    with served(graph):
        a.publish(cdr("a0"))
        a.publish(cdr("a1"))
        c.publish(cdr("c0"))  # a plain subscriber: delivered now, after the batch
        assert log.texts() == ["a0", "a1", "c0"]
        a.publish({"data": "a2"})  # values, not bytes: delivered now
        a.publish(cdr("a3"))
        assert log.texts() == ["a0", "a1", "c0", "a2"]
        await anyio.lowlevel.checkpoint()
    assert log.texts() == ["a0", "a1", "c0", "a2", "a3"]


async def test_a_topic_with_a_plain_subscriber_is_delivered_at_once() -> None:
    graph, log = Graph(), Log()
    subscribe(graph, "fox", "/a", Queueing(log, "fox"))
    graph.create_subscription("/a", lambda msg: log.entries.append(("py", str(msg["data"]))))
    publisher = graph.create_publisher("/a", STRING)
    with served(graph):
        publisher.publish(cdr("a0"))
        publisher.publish(cdr("a1"))
        assert log.texts() == ["a0", "a0", "a1", "a1"]  # each sink as it was published


async def test_subscribing_in_the_turn_delivers_the_batch_to_the_earlier_subscribers() -> None:
    graph, log = Graph(), Log()
    subscribe(graph, "early", "/a", Queueing(log, "early"))
    publisher = graph.create_publisher("/a", STRING)
    with served(graph):
        publisher.publish(cdr("a0"))
        publisher.publish(cdr("a1"))
        subscribe(graph, "late", "/a", Queueing(log, "late"))
        assert log.entries == [("early", "a0"), ("early", "a1")]
        publisher.publish(cdr("a2"))
        publisher.publish(cdr("a3"))
        graph.port.unsubscribe("early", "/a")
        publisher.publish(cdr("a4"))
        publisher.publish(cdr("a5"))
        await anyio.lowlevel.checkpoint()
    assert log.texts("early") == ["a0", "a1", "a2", "a3"]
    assert log.texts("late") == ["a2", "a3", "a4", "a5"]


async def test_after_a_batch_of_one_the_next_messages_go_at_once_then_batch_again() -> None:
    graph, log, publisher = one_topic()
    with served(graph):
        publisher.publish(cdr("first"))
        await anyio.lowlevel.checkpoint()  # a batch of one
        for i in range(SOLO_AFTER_ONE):  # a publisher that yields after each message
            publisher.publish(cdr(f"solo{i}"))
            assert log.texts()[-1] == f"solo{i}"  # delivered as published
            await anyio.lowlevel.checkpoint()
        for i in range(3):
            publisher.publish(cdr(f"burst{i}"))
        assert log.texts()[-1] == f"solo{SOLO_AFTER_ONE - 1}"  # batched again
        await anyio.lowlevel.checkpoint()
    assert log.batches[-1] == ("fox", 3)
    assert len(log.texts()) == 1 + SOLO_AFTER_ONE + 3


async def test_a_turn_that_never_ends_holds_a_bounded_batch_in_the_graph() -> None:
    graph, log, publisher = one_topic()
    with served(graph):
        for i in range(BATCH_MAX_MESSAGES * 2 + 5):
            publisher.publish(cdr(f"m{i}"))
        assert [size for _, size in log.batches] == [BATCH_MAX_MESSAGES] * 2
        big = "x" * (BATCH_MAX_BYTES // 4)
        for _ in range(4):  # the fourth reaches the bytes' bound
            publisher.publish(cdr(big))
        assert [size for _, size in log.batches][2:] == [9]
        await anyio.lowlevel.checkpoint()
    assert len(log.texts()) == BATCH_MAX_MESSAGES * 2 + 9
    assert log.texts()[: BATCH_MAX_MESSAGES * 2 + 5] == [
        f"m{i}" for i in range(BATCH_MAX_MESSAGES * 2 + 5)
    ]


async def test_latched_messages_and_graphs_with_taps_are_delivered_at_once() -> None:
    graph, log = Graph(), Log()
    subscribe(graph, "fox", "/latched", Queueing(log, "fox"))
    subscribe(graph, "fox", "/tapped", Queueing(log, "fox"))
    latched = graph.create_publisher("/latched", STRING, latch=True)
    tapped = graph.create_publisher("/tapped", STRING)
    with served(graph):
        latched.publish(cdr("kept"))
        assert log.texts() == ["kept"]
        graph.port.taps.append(lambda topic, event, client, latch: None)
        tapped.publish(cdr("seen by the tap"))
        assert log.texts() == ["kept", "seen by the tap"]
    late = Log()
    subscribe(graph, "late", "/latched", Queueing(late, "late"))
    assert late.texts() == ["kept"]


async def test_a_tap_that_appears_in_the_turn_sees_the_batch() -> None:
    graph, log, publisher = one_topic()
    tapped: list[str] = []
    with served(graph):
        publisher.publish(cdr("a0"))
        publisher.publish(cdr("a1"))
        graph.port.taps.append(lambda topic, event, client, latch: tapped.append(text_of(event)))
        await anyio.lowlevel.checkpoint()
    assert tapped == ["a0", "a1"]
    assert log.texts() == ["a0", "a1"]


async def test_a_batch_open_when_serving_ends_is_delivered_then() -> None:
    graph, log, publisher = one_topic()
    with served(graph):
        publisher.publish(cdr("a0"))
        publisher.publish(cdr("a1"))
    assert log.texts() == ["a0", "a1"]
    publisher.publish(cdr("a2"))  # no server: at once
    assert log.texts() == ["a0", "a1", "a2"]


async def test_switched_off_every_message_is_delivered_as_published(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    switch_off(monkeypatch, "batched-delivery")
    graph, log, publisher = one_topic()
    with served(graph):
        for i in range(3):
            publisher.publish(cdr(f"a{i}"))
        assert log.texts() == ["a0", "a1", "a2"]
    assert log.batches == [("fox", 1)] * 3


def test_without_a_loop_every_message_is_delivered_as_published() -> None:
    _, log, publisher = one_topic()
    publisher.publish(cdr("a0"))
    publisher.publish(cdr("a1"))
    assert log.texts() == ["a0", "a1"]


async def test_a_failing_sink_leaves_the_others_their_batch(
    caplog: pytest.LogCaptureFixture,
) -> None:
    graph, log = Graph(), Log()

    class Broken(Queueing):
        def on_messages(self, events: list[MessageEvent]) -> None:
            raise RuntimeError("broken")

    topic = f"/a{uuid.uuid4().hex}"  # its own: a failure is logged once per topic and episode
    subscribe(graph, "broken", topic, Broken(log, "broken"))
    subscribe(graph, "fox", topic, Queueing(log, "fox"))
    publisher = graph.create_publisher(topic, STRING)
    with served(graph):
        publisher.publish(cdr("a0"))
        publisher.publish(cdr("a1"))
        await anyio.lowlevel.checkpoint()
    assert log.texts("fox") == ["a0", "a1"]
    assert f"subscriber broken of {topic} failed" in caplog.text


async def test_a_run_from_a_link_goes_after_the_turns_batch_and_past_its_taps() -> None:
    # A link's run of samples (``GraphCore.deliver_many``): one call per sink that takes
    # runs, after what the turn's batch holds, and each sample seen by the graph's taps.
    graph, log, publisher = one_topic()
    graph.port.advertise("link", "/a", STRING)
    tapped: list[str] = []
    with served(graph):
        publisher.publish(cdr("a0"))  # waits for the turn's end
        graph.port.publish_local_many("link", "/a", [None, None], [cdr("r0"), cdr("r1")])
        assert log.texts() == ["a0", "r0", "r1"]
        graph.port.taps.append(lambda topic, event, client, latch: tapped.append(text_of(event)))
        graph.port.publish_local_many("link", "/a", [None, None], [cdr("r2"), cdr("r3")])
    assert log.batches == [("fox", 1), ("fox", 2), ("fox", 2)]
    assert tapped == ["r2", "r3"]
    with pytest.raises(GraphError, match="publisher of /a"):
        graph.port.publish_local_many("stranger", "/a", [None], [cdr("x")])
