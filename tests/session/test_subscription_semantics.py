"""Throttle, queue, merging, unsubscribe by id and latching (spec 3.3.4-3.3.5, D11-D13).

Time is injected: the graph's FakeClock stamps each publish, and the session's
timers run when the test calls ``handle_timer``. REF §5.3's numbers are
reproduced under our decisions (leading edge plus trailing send, drop oldest).
"""

from __future__ import annotations

import json

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from tests.conftest import FakeClock, Peer


def data(peer: Peer) -> list[object]:
    return [m["msg"]["data"] for m in peer.received() if m["op"] == "publish"]  # type: ignore[index]


def publish_at(clock: FakeClock, pub: Peer, t: float, value: object, topic: str = "/t") -> None:
    clock.now = t
    pub.send(op="publish", topic=topic, msg={"data": value})


def run_timers(peer: Peer, clock: FakeClock, until: float) -> None:
    """Advance to ``until``, running every timer due on the way at its own deadline."""
    while (deadline := peer.session.get_timer()) is not None and deadline <= until:
        clock.now = deadline
        peer.session.handle_timer(deadline)
    clock.now = until


def setup(graph: Graph, **subscribe: object) -> tuple[Peer, Peer]:
    pub, sub = Peer(graph, "pub"), Peer(graph, "sub", StatusLevel.WARNING)
    pub.send(op="advertise", topic="/t", type="std_msgs/String")
    sub.send(op="subscribe", topic="/t", id="s", **subscribe)
    return pub, sub


def test_without_throttle_every_message_goes_out_at_once(graph: Graph, clock: FakeClock) -> None:
    pub, sub = setup(graph, queue_length=3)
    for i in range(10):
        publish_at(clock, pub, 100.0, str(i))
    assert data(sub) == [str(i) for i in range(10)]
    assert sub.session.get_timer() is None


def test_ref_5_3_throttle_10_s_queue_10_keeps_the_last_ten(graph: Graph, clock: FakeClock) -> None:
    # REF §5.3: "hello" immediately, then after throttle -> 0 exactly 990..999.
    pub, sub = setup(graph, throttle_rate=10_000, queue_length=10)
    publish_at(clock, pub, 100.0, "hello")
    for i in range(1000):
        publish_at(clock, pub, 100.0 + i * 0.001, str(i))
    assert data(sub) == ["hello"]
    sub.send(op="subscribe", topic="/t", id="s", throttle_rate=0, queue_length=10)
    assert data(sub) == [str(i) for i in range(990, 1000)]
    assert sub.session.get_timer() is None


def test_ref_5_3_queue_5_paced_at_one_per_second(graph: Graph, clock: FakeClock) -> None:
    # REF §5.3: queue 5, a consumer taking 1 s per message, 25 messages 10 ms
    # apart -> [0, 20, 21, 22, 23, 24]. Here the pace is throttle_rate 1000 ms.
    pub, sub = setup(graph, throttle_rate=1000, queue_length=5)
    for i in range(25):
        publish_at(clock, pub, 100.0 + i * 0.01, str(i))
    assert data(sub) == ["0"]
    delivered = ["0"]
    for second in range(1, 7):
        run_timers(sub, clock, 100.0 + second)
        delivered += data(sub)
    assert delivered == ["0", "20", "21", "22", "23", "24"]
    assert sub.session.get_timer() is None


def test_d12_throttle_without_queue_sends_the_latest_at_the_window_end(
    graph: Graph, clock: FakeClock
) -> None:
    # The reference loses "c"; D12 delivers the latest of the burst when the window ends.
    pub, sub = setup(graph, throttle_rate=500)
    publish_at(clock, pub, 100.0, "a")
    publish_at(clock, pub, 100.1, "b")
    publish_at(clock, pub, 100.2, "c")
    assert data(sub) == ["a"]
    assert sub.session.get_timer() == 100.5
    run_timers(sub, clock, 100.5)
    assert data(sub) == ["c"]
    publish_at(clock, pub, 100.7, "d")  # inside the new window that "c" opened
    run_timers(sub, clock, 100.99)
    assert data(sub) == []
    run_timers(sub, clock, 101.0)
    assert data(sub) == ["d"]
    publish_at(clock, pub, 102.0, "e")  # a quiet period: leading edge again
    assert data(sub) == ["e"]


def test_merged_throttle_is_the_lowest_and_unsubscribe_by_id_keeps_the_rest(
    graph: Graph, clock: FakeClock
) -> None:
    pub, sub = setup(graph, throttle_rate=1000)
    sub.send(op="subscribe", topic="/t", id="fast", throttle_rate=0)
    publish_at(clock, pub, 100.0, "1")
    publish_at(clock, pub, 100.1, "2")
    assert data(sub) == ["1", "2"]  # one copy per message (D11)
    sub.send(op="unsubscribe", topic="/t", id="fast")
    publish_at(clock, pub, 100.2, "3")
    assert data(sub) == []  # throttled again by "s"
    run_timers(sub, clock, 101.1)
    assert data(sub) == ["3"]
    sub.send(op="unsubscribe", topic="/t", id="unknown")
    [status] = sub.statuses()
    assert status["level"] == "warning" and status["id"] == "unknown"
    publish_at(clock, pub, 103.0, "4")
    assert data(sub) == ["4"]


def test_merged_queue_length_is_the_highest(graph: Graph, clock: FakeClock) -> None:
    pub, sub = setup(graph, throttle_rate=1000, queue_length=1)
    sub.send(op="subscribe", topic="/t", id="deep", throttle_rate=1000, queue_length=3)
    for i in range(6):
        publish_at(clock, pub, 100.0 + i * 0.01, str(i))
    sub.send(op="unsubscribe", topic="/t", id="deep")  # queue shrinks to 1: the newest stays
    run_timers(sub, clock, 105.0)
    assert data(sub) == ["0", "5"]


def test_unsubscribe_cancels_pending_sends(graph: Graph, clock: FakeClock) -> None:
    pub, sub = setup(graph, throttle_rate=1000, queue_length=5)
    publish_at(clock, pub, 100.0, "a")
    publish_at(clock, pub, 100.1, "b")
    sub.send(op="unsubscribe", topic="/t")
    assert sub.session.get_timer() is None
    run_timers(sub, clock, 110.0)
    assert data(sub) == ["a"]


def test_a_timer_wakes_the_transport(graph: Graph, clock: FakeClock) -> None:
    pub, sub = setup(graph, throttle_rate=1000)
    wakes: list[int] = []
    sub.session._on_output = lambda: wakes.append(1)
    publish_at(clock, pub, 100.0, "a")
    assert wakes == [1]  # a frame
    sub.session.frames_to_send()
    publish_at(clock, pub, 100.1, "b")
    assert wakes == [1, 1]  # the trailing-send timer


def test_a_late_subscriber_gets_the_latched_message_once(graph: Graph, clock: FakeClock) -> None:
    pub = Peer(graph, "pub")
    pub.send(op="advertise", topic="/map", type="std_msgs/String", latch=True)
    pub.send(op="publish", topic="/map", msg={"data": "old"})
    pub.send(op="publish", topic="/map", msg={"data": "map"})
    late = [Peer(graph, f"late{i}") for i in range(3)]
    for peer in late:
        peer.send(op="subscribe", topic="/map", id="a", throttle_rate=1000)
        peer.send(op="subscribe", topic="/map", id="b", compression="cbor")
    for peer in late:
        [frame] = peer.session.frames_to_send()
        assert json.loads(frame.data) == {"op": "publish", "topic": "/map", "msg": {"data": "map"}}


def test_latch_on_publish_and_its_end_with_the_publisher(graph: Graph) -> None:
    pub = Peer(graph, "pub")
    pub.send(op="advertise", topic="/l", type="std_msgs/String")
    pub.send(op="publish", topic="/l", msg={"data": "kept"}, latch=True)
    first = Peer(graph, "first")
    first.send(op="subscribe", topic="/l")
    assert data(first) == ["kept"]
    pub.send(op="unadvertise", topic="/l")
    second = Peer(graph, "second")
    second.send(op="subscribe", topic="/l")
    assert data(second) == []


def test_unlatched_messages_are_not_replayed(graph: Graph) -> None:
    pub = Peer(graph, "pub")
    pub.send(op="advertise", topic="/u", type="std_msgs/String")
    pub.send(op="publish", topic="/u", msg={"data": "gone"})
    sub = Peer(graph, "sub")
    sub.send(op="subscribe", topic="/u")
    assert data(sub) == []


def test_in_process_latched_publisher(graph: Graph) -> None:
    publisher = graph.create_publisher("/state", "std_msgs/msg/String", latch=True)
    publisher.publish({"data": "ready"})
    sub = Peer(graph, "sub", StatusLevel.ERROR)
    sub.send(op="subscribe", topic="state", compression="cbor")
    frames = sub.session.frames_to_send()
    assert len(frames) == 1 and frames[0].binary
    publisher.close()
    again = Peer(graph, "again")
    again.send(op="subscribe", topic="/state", type="std_msgs/String")
    assert data(again) == []


def test_queue_length_is_capped_with_a_warning(graph: Graph, clock: FakeClock) -> None:
    pub, sub = setup(graph, throttle_rate=1000, queue_length=1_000_000)
    [status] = sub.statuses()
    assert status == {
        "op": "status",
        "level": "warning",
        "msg": "subscribe: queue_length 1000000 capped at 100",
        "id": "s",
    }
    for i in range(300):
        publish_at(clock, pub, 100.0 + i * 0.001, str(i))
    assert [m for m in sub.statuses()] == []
    subscription = sub.session.holdings.subscriptions["/t"]
    assert len(subscription.queue) == 100
    assert subscription.queue[0].msg == {"data": "200"}
