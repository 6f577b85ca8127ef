"""A session's lossy lane (D36): subscriptions made on a lossy channel, latest-only per topic."""

from __future__ import annotations

import json

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.lossy import LossyLane
from rwt_protocol.runtime.outbox import OutFrame
from tests.conftest import Peer


class LossyPeer(Peer):
    """A peer whose transport has a lossy channel: a lane open on its session."""

    def __init__(self, graph: Graph, name: str, max_message_bytes: int = 0) -> None:
        super().__init__(graph, name, level=StatusLevel.WARNING)
        self.wakes = 0
        self.lane = self.session.open_lossy_lane(max_message_bytes, self._woken)

    def _woken(self) -> None:
        self.wakes += 1

    def send_lossy(self, **op: object) -> None:
        self.session.receive_lossy_frame(json.dumps(op), self.clock.monotonic())

    def lossy_received(self) -> list[dict[str, object]]:
        frames = []
        while (frame := self.session.lossy_frame_to_send()) is not None:
            frames.append(json.loads(frame.data))
        return frames


def _publishes(messages: list[dict[str, object]]) -> list[dict[str, object]]:
    return [m for m in messages if m["op"] == "publish"]


def test_a_subscription_made_on_the_lossy_channel_gets_only_the_latest_message(
    graph: Graph,
) -> None:
    peer = LossyPeer(graph, "p")
    counter = graph.create_publisher("/count", "std_msgs/msg/Int32")
    peer.send_lossy(op="subscribe", topic="/count", type="std_msgs/Int32")
    for value in range(5):
        counter.publish({"data": value})
    assert _publishes(peer.received()) == []  # nothing of it on the reliable channel
    assert peer.lossy_received() == [{"op": "publish", "topic": "/count", "msg": {"data": 4}}]
    assert peer.lane.replaced == 4
    assert peer.wakes == 1  # woken when the lane got its first message, not per message
    counter.publish({"data": 5})
    assert [m["msg"] for m in peer.lossy_received()] == [{"data": 5}]


def test_replies_to_ops_on_the_lossy_channel_come_on_the_reliable_one(graph: Graph) -> None:
    peer = LossyPeer(graph, "p")
    peer.send_lossy(op="subscribe", topic="/count", type="std_msgs/Int32", id="s1")
    peer.send_lossy(op="subscribe", topic="/nowhere", type="no_such/Type", id="s2")
    statuses = peer.statuses()
    assert any(s["id"] == "s2" and s["level"] == "error" for s in statuses)
    assert peer.lossy_received() == []


def test_topics_wait_in_the_order_they_came_each_with_its_latest_message(graph: Graph) -> None:
    peer = LossyPeer(graph, "p")
    a = graph.create_publisher("/a", "std_msgs/msg/Int32")
    b = graph.create_publisher("/b", "std_msgs/msg/Int32")
    peer.send_lossy(op="subscribe", topic="/a", type="std_msgs/Int32")
    peer.send_lossy(op="subscribe", topic="/b", type="std_msgs/Int32")
    a.publish({"data": 1})
    b.publish({"data": 2})
    a.publish({"data": 3})
    assert [(m["topic"], m["msg"]) for m in peer.lossy_received()] == [
        ("/a", {"data": 3}),
        ("/b", {"data": 2}),
    ]


def test_a_reliable_subscription_beside_it_keeps_every_message_on_the_outbox(
    graph: Graph,
) -> None:
    peer = LossyPeer(graph, "p")
    counter = graph.create_publisher("/count", "std_msgs/msg/Int32")
    peer.send(op="subscribe", topic="/count", type="std_msgs/Int32")  # the reliable channel
    for value in range(3):
        counter.publish({"data": value})
    assert [m["msg"] for m in _publishes(peer.received())] == [{"data": v} for v in range(3)]
    assert peer.lossy_received() == []


def test_one_id_from_the_reliable_channel_makes_the_merged_subscription_reliable(
    graph: Graph,
) -> None:
    peer = LossyPeer(graph, "p")
    counter = graph.create_publisher("/count", "std_msgs/msg/Int32")
    peer.send_lossy(op="subscribe", topic="/count", type="std_msgs/Int32", id="fast")
    peer.send(op="subscribe", topic="/count", type="std_msgs/Int32", id="every")
    counter.publish({"data": 1})
    counter.publish({"data": 2})
    assert [m["msg"] for m in _publishes(peer.received())] == [{"data": 1}, {"data": 2}]
    assert peer.lossy_received() == []
    peer.send(op="unsubscribe", topic="/count", id="every")  # lossy ids only again
    peer.received()
    counter.publish({"data": 3})
    counter.publish({"data": 4})
    assert _publishes(peer.received()) == []
    assert [m["msg"] for m in peer.lossy_received()] == [{"data": 4}]


def test_a_message_over_the_lane_limit_is_dropped_with_one_warning_per_topic(
    graph: Graph,
) -> None:
    peer = LossyPeer(graph, "p", max_message_bytes=200)
    text = graph.create_publisher("/text", "std_msgs/msg/String")
    peer.send_lossy(op="subscribe", topic="/text", type="std_msgs/String")
    peer.received()
    for _ in range(3):
        text.publish({"data": "x" * 500})
    warnings = [s for s in peer.statuses() if s["level"] == "warning"]
    assert len(warnings) == 1
    assert "/text" in str(warnings[0]["msg"]) and "200 bytes" in str(warnings[0]["msg"])
    assert peer.lossy_received() == []
    assert peer.lane.refused == 3
    text.publish({"data": "small"})  # one that fits still goes
    assert [m["msg"] for m in peer.lossy_received()] == [{"data": "small"}]


def test_fragment_size_is_ignored_on_the_lane(graph: Graph) -> None:
    peer = LossyPeer(graph, "p")
    text = graph.create_publisher("/text", "std_msgs/msg/String")
    peer.send_lossy(op="subscribe", topic="/text", type="std_msgs/String", fragment_size=10)
    text.publish({"data": "y" * 100})
    assert [m["msg"] for m in peer.lossy_received()] == [{"data": "y" * 100}]


def test_without_the_lane_the_subscriptions_messages_go_on_the_reliable_channel(
    graph: Graph,
) -> None:
    peer = LossyPeer(graph, "p")
    counter = graph.create_publisher("/count", "std_msgs/msg/Int32")
    peer.send_lossy(op="subscribe", topic="/count", type="std_msgs/Int32")
    counter.publish({"data": 1})
    peer.session.close_lossy_lane()  # the lossy channel closed
    counter.publish({"data": 2})
    assert [m["msg"] for m in _publishes(peer.received())] == [{"data": 2}]
    assert peer.session.lossy_frame_to_send() is None


def test_the_lane_holds_at_most_its_byte_limit_dropping_the_oldest_topics() -> None:
    lane = LossyLane(0, limit_bytes=250, on_output=lambda: None)
    for topic in ("/a", "/b", "/c"):
        assert lane.put(topic, OutFrame(b"z" * 100))
    assert len(lane) == 2 and lane.queued_bytes == 200 and lane.dropped == 1
    frame = lane.pop()
    assert frame is not None and lane.queued_bytes == 100
    assert lane.pop() is not None and lane.pop() is None
