"""Protocol 2.1.0's ``qos`` through two sessions on one graph (D62-D65), on a hand-moved clock.

What a client sees: the frames its session gives the transport, taken at a time the
test chooses (``frames_to_send(None, now)``), as the pump takes them.
"""

from __future__ import annotations

import json
from dataclasses import replace

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.qos import MAX_DEPTH
from rwt_protocol.server.session import SessionConfig
from tests.conftest import FakeClock, Peer

STRING = "std_msgs/msg/String"
DURABLE = {"durability": "transient_local"}


def _taken(peer: Peer, now: float | None = None) -> list[dict[str, object]]:
    return [json.loads(f.data) for f in peer.session.frames_to_send(None, now)]


def _data(frames: list[dict[str, object]]) -> list[object]:
    return [f["msg"]["data"] for f in frames if f["op"] == "publish"]  # type: ignore[index]


def _publish(peer: Peer, *texts: str) -> None:
    for text in texts:
        peer.send(op="publish", topic="/t", msg={"data": text})


def test_a_late_transient_local_subscriber_gets_the_last_n_in_order(graph: Graph) -> None:
    for depth in (1, 5):
        pub, late, volatile, plain = (Peer(graph, f"{n}{depth}") for n in "pvqr")
        topic = f"/d{depth}"
        qos = {**DURABLE, "depth": depth}
        pub.send(op="advertise", topic=topic, type=STRING, qos=qos)
        for i in range(8):
            pub.send(op="publish", topic=topic, msg={"data": f"m{i}"})
        late.send(op="subscribe", topic=topic, qos=qos)
        volatile.send(op="subscribe", topic=topic, qos={"durability": "volatile"})
        plain.send(op="subscribe", topic=topic)  # no qos: the adaptive default takes them
        expected = [f"m{i}" for i in range(8 - depth, 8)]
        assert _data(_taken(late)) == expected
        assert _data(_taken(plain)) == expected
        assert _taken(volatile) == []
        pub.send(op="publish", topic=topic, msg={"data": "new"})
        assert _data(_taken(late)) == _data(_taken(volatile)) == ["new"]


def test_a_late_subscriber_with_a_shallower_history_gets_fewer(graph: Graph) -> None:
    pub, late = Peer(graph, "p"), Peer(graph, "s")
    pub.send(op="advertise", topic="/t", type=STRING, qos={**DURABLE, "depth": 5})
    _publish(pub, *"abcde")
    late.send(op="subscribe", topic="/t", qos={**DURABLE, "depth": 2})
    assert _data(_taken(late)) == ["d", "e"]


def test_the_kept_messages_go_with_the_offer(graph: Graph) -> None:
    pub, late = Peer(graph, "p"), Peer(graph, "s")
    pub.send(op="advertise", topic="/t", type=STRING, qos={**DURABLE, "depth": 3})
    other = Peer(graph, "o")
    other.send(op="subscribe", topic="/t", type=STRING)  # keeps the topic alive
    _publish(pub, "a")
    pub.send(op="unadvertise", topic="/t")
    late.send(op="subscribe", topic="/t", qos=DURABLE)
    assert _taken(late) == []


def test_a_stored_message_past_its_lifespan_is_not_replayed(graph: Graph, clock: FakeClock) -> None:
    pub = Peer(graph, "p")
    pub.send(op="advertise", topic="/t", type=STRING, qos={**DURABLE, "depth": 5, "lifespan": 0.5})
    _publish(pub, "old")
    clock.now += 0.4
    _publish(pub, "fresh")
    clock.now += 0.2  # "old" is 0.6 s old, "fresh" 0.2 s
    late = Peer(graph, "s")
    late.send(op="subscribe", topic="/t", qos=DURABLE)
    assert _data(_taken(late, clock.now)) == ["fresh"]


def test_a_queued_message_past_its_lifespan_is_never_taken(graph: Graph, clock: FakeClock) -> None:
    pub, sub = Peer(graph, "p"), Peer(graph, "s")
    pub.send(op="advertise", topic="/t", type=STRING)
    sub.send(op="subscribe", topic="/t", qos={"lifespan": 0.2})
    for i in range(10):  # the subscriber's link stalls: nothing is taken meanwhile
        _publish(pub, f"m{i}")
        clock.now += 0.05
    # taken at 100.5: m0 (100.0) .. m5 (100.25) are past 0.2 s; m6 (100.3) is not
    assert _data(_taken(sub, clock.now)) == ["m6", "m7", "m8", "m9"]
    assert sub.session.stats.expired_messages == 6


def test_the_topics_lifespan_binds_a_subscriber_that_gave_none(
    graph: Graph, clock: FakeClock
) -> None:
    pub, sub = Peer(graph, "p"), Peer(graph, "s")
    pub.send(op="advertise", topic="/t", type=STRING, qos={"lifespan": {"secs": 1, "nsecs": 0}})
    sub.send(op="subscribe", topic="/t")
    _publish(pub, "a")
    clock.now += 2
    _publish(pub, "b")
    assert _data(_taken(sub, clock.now)) == ["b"]


def test_the_servers_default_lifespan_binds_subscriptions_without_one(
    graph: Graph, clock: FakeClock
) -> None:
    config = replace(SessionConfig(), qos_lifespan_s=1.0)
    pub, sub = Peer(graph, "p"), Peer(graph, "s", config=config)
    own = Peer(graph, "o", config=config)
    pub.send(op="advertise", topic="/t", type=STRING)
    sub.send(op="subscribe", topic="/t")
    own.send(op="subscribe", topic="/t", qos={"lifespan": 5})
    _publish(pub, "a")
    clock.now += 2
    _publish(pub, "b")
    assert _data(_taken(sub, clock.now)) == ["b"]
    assert _data(_taken(own, clock.now)) == ["a", "b"]


def test_depth_bounds_what_a_subscribers_queue_keeps(graph: Graph) -> None:
    pub, sub, plain = Peer(graph, "p"), Peer(graph, "s"), Peer(graph, "q")
    pub.send(op="advertise", topic="/t", type=STRING)
    sub.send(op="subscribe", topic="/t", qos={"depth": 3})
    plain.send(op="subscribe", topic="/t")
    _publish(pub, *"abcdefg")
    assert _data(_taken(sub)) == ["e", "f", "g"]
    assert _data(_taken(plain)) == list("abcdefg")
    assert sub.session.stats.dropped_frames == 4


def test_depth_bounds_a_throttled_subscriptions_queue_too(graph: Graph, clock: FakeClock) -> None:
    pub, sub = Peer(graph, "p"), Peer(graph, "s")
    pub.send(op="advertise", topic="/t", type=STRING)
    sub.send(op="subscribe", topic="/t", throttle_rate=1000, queue_length=50, qos={"depth": 2})
    _publish(pub, *"abcde")  # "a" goes at once, the rest waits for the window
    assert _data(_taken(sub)) == ["a"]
    clock.now += 1
    sub.session.handle_timer(clock.now)
    clock.now += 1
    sub.session.handle_timer(clock.now)
    assert _data(_taken(sub)) == ["d", "e"]


def test_a_hostile_depth_is_capped_with_a_warning(graph: Graph) -> None:
    sub = Peer(graph, "s", level=StatusLevel.WARNING)
    pub = Peer(graph, "p", level=StatusLevel.WARNING)
    pub.send(op="advertise", topic="/t", type=STRING, qos={**DURABLE, "depth": 10**9}, id="a")
    sub.send(op="subscribe", topic="/t", qos={"depth": 10**9}, id="s")
    assert pub.statuses() == [
        {
            "op": "status",
            "level": "warning",
            "msg": f"advertise: qos.depth 1000000000 capped at {MAX_DEPTH}",
            "id": "a",
        }
    ]
    assert sub.statuses() == [
        {
            "op": "status",
            "level": "warning",
            "msg": f"subscribe: qos.depth 1000000000 capped at {MAX_DEPTH}",
            "id": "s",
        }
    ]
    for i in range(MAX_DEPTH + 5):
        pub.send(op="publish", topic="/t", msg={"data": str(i)})
    state = graph.topics["/t"].qos
    assert state is not None and len(state.store) == MAX_DEPTH


def test_a_bad_qos_is_refused_naming_the_field_and_registers_nothing(graph: Graph) -> None:
    pub, sub = Peer(graph, "p"), Peer(graph, "s")
    pub.send(
        op="advertise", topic="/t", type=STRING, qos={"depth": -3, "durability": "forever"}, id=1
    )
    [status] = pub.statuses()
    assert status["level"] == "error" and status["id"] == 1
    assert status["msg"] == "advertise: expected a number >= 0, got -3 at $.qos.depth"
    assert "/t" not in graph.topics
    sub.send(op="subscribe", topic="/t", type=STRING, qos={"lifespan": "soon"}, id=2)
    assert "$.qos.lifespan" in str(sub.statuses()[0]["msg"])
    assert "/t" not in graph.topics
    pub.send(op="publish", topic="/t", type=STRING, msg={"data": "x"}, qos={"reliability": 1})
    assert "$.qos.reliability" in str(pub.statuses()[0]["msg"])
    assert "/t" not in graph.topics
    # the topic is usable after
    pub.send(op="advertise", topic="/t", type=STRING, qos=DURABLE)
    sub.send(op="subscribe", topic="/t", qos=DURABLE)
    _publish(pub, "ok")
    assert _data(_taken(sub)) == ["ok"]
    assert pub.statuses() == []


def test_the_first_registration_fixes_the_topics_qos(graph: Graph) -> None:
    first = Peer(graph, "a")
    second = Peer(graph, "b", level=StatusLevel.WARNING)
    first.send(op="advertise", topic="/t", type=STRING, qos={**DURABLE, "depth": 2})
    second.send(op="advertise", topic="/t", type=STRING, qos={"depth": 7}, id="b1")
    warnings = [s for s in second.statuses() if s["level"] == "warning"]
    assert warnings == [
        {
            "op": "status",
            "level": "warning",
            "msg": "advertise: /t keeps the QoS of its first registration"
            " (keep_last 2, reliable, transient_local); this one's"
            " (keep_last 7, reliable, volatile) is not used",
            "id": "b1",
        }
    ]
    _publish(second, "x", "y", "z")  # through the topic's one offer: kept, 2 of them
    late = Peer(graph, "late")
    late.send(op="subscribe", topic="/t")
    assert _data(_taken(late)) == ["y", "z"]


def test_a_publish_with_type_and_qos_registers_as_advertise_does(graph: Graph) -> None:
    pub, late = Peer(graph, "p"), Peer(graph, "s")
    qos = {**DURABLE, "depth": 2}
    pub.send(op="publish", topic="/t", type=STRING, qos=qos, msg={"data": "a"})
    _publish(pub, "b", "c")
    pub.send(op="publish", topic="/t", qos={"depth": -1}, msg={"data": "d"})  # a model error
    assert "$.qos.depth" in str(pub.statuses()[0]["msg"])
    late.send(op="subscribe", topic="/t", qos=DURABLE)
    assert _data(_taken(late)) == ["b", "c"]


def test_with_qos_latch_and_queue_size_are_not_read(graph: Graph) -> None:
    pub, late = Peer(graph, "p"), Peer(graph, "s")
    pub.send(op="advertise", topic="/t", type=STRING, latch=True, queue_size=1, qos={})
    _publish(pub, "a")
    late.send(op="subscribe", topic="/t")
    assert _taken(late) == []  # {} is volatile: nothing latched


def test_an_incompatible_subscriber_is_told_and_gets_nothing_while_the_offer_stands(
    graph: Graph,
) -> None:
    pub = Peer(graph, "p")
    sub = Peer(graph, "s", level=StatusLevel.WARNING)
    pub.send(op="advertise", topic="/t", type=STRING, qos={"reliability": "best_effort"})
    sub.send(op="subscribe", topic="/t", qos={"reliability": "reliable"}, id="s1")
    [warning] = [s for s in sub.statuses() if s["level"] == "warning"]
    assert warning["id"] == "s1"
    assert warning["msg"] == (
        "subscribe: /t offers keep_last 10, best_effort, volatile, incompatible with this"
        " subscription (reliability: reliable asked of a best_effort publisher): no message"
        " reaches it while that offer stands, as in ROS 2"
    )
    _publish(pub, "lost")
    assert _taken(sub) == []
    pub.send(op="unadvertise", topic="/t")  # the offer goes: the subscription matches again
    other = Peer(graph, "o")
    other.send(op="publish", topic="/t", msg={"data": "plain"})
    assert _data(_taken(sub)) == ["plain"]


def test_transient_local_asked_of_a_volatile_offer_is_incompatible(graph: Graph) -> None:
    pub = Peer(graph, "p")
    sub = Peer(graph, "s", level=StatusLevel.WARNING)
    sub.send(op="subscribe", topic="/t", type=STRING, qos=DURABLE)
    assert sub.statuses() == []
    pub.send(op="advertise", topic="/t", type=STRING, qos={"durability": "volatile"})
    [warning] = sub.statuses()  # told when the offer comes, after it subscribed
    assert "durability: transient_local asked of a volatile publisher" in str(warning["msg"])
    _publish(pub, "x")
    assert _taken(sub) == []


def test_best_available_matches_what_is_offered(graph: Graph) -> None:
    pub = Peer(graph, "p")
    sub = Peer(graph, "s", level=StatusLevel.WARNING)
    pub.send(op="advertise", topic="/t", type=STRING, qos={"reliability": "best_effort"})
    sub.send(op="subscribe", topic="/t", qos={"reliability": "best_available"})
    _publish(pub, "x")
    assert _data(_taken(sub)) == ["x"]


def test_best_effort_is_dropped_first_under_pressure(graph: Graph) -> None:
    config = replace(SessionConfig(), send_buffer_limit=64 * 1024)
    pub = Peer(graph, "p")
    sub = Peer(graph, "s", config=config)
    for name in ("/be", "/rel"):
        pub.send(op="advertise", topic=name, type=STRING)
    sub.send(op="subscribe", topic="/be", qos={"reliability": "best_effort", "depth": 100})
    sub.send(op="subscribe", topic="/rel", qos={"reliability": "reliable", "history": "keep_all"})
    outbox = sub.session.outbox
    for i in range(60):  # the subscriber reads nothing: about 420 B a message queued
        if i < 40:
            pub.send(op="publish", topic="/rel", msg={"data": f"r{i:03}" + "x" * 200})
        pub.send(op="publish", topic="/be", msg={"data": f"b{i:03}" + "x" * 200})
        # best effort never pushes the queue past its high watermark: no publisher held for it
        assert outbox.fill_bytes <= outbox.high_water_bytes
    frames = _taken(sub)
    by_topic: dict[object, list[str]] = {"/be": [], "/rel": []}
    for frame, data in zip(frames, _data(frames), strict=True):
        by_topic[frame["topic"]].append(str(data)[:4])
    assert by_topic["/rel"] == [f"r{i:03}" for i in range(40)]  # reliable: all kept
    assert 0 < len(by_topic["/be"]) < 60
    assert by_topic["/be"][-1] == "b059"  # the newest stays


def test_a_missed_deadline_warns_once_per_episode(graph: Graph, clock: FakeClock) -> None:
    pub = Peer(graph, "p")
    sub = Peer(graph, "s", level=StatusLevel.WARNING)
    pub.send(op="advertise", topic="/t", type=STRING)
    sub.send(op="subscribe", topic="/t", qos={"deadline": 0.5}, id="d")
    _publish(pub, "a")
    for _ in range(10):  # 2 s of silence: one warning
        clock.now += 0.2
        sub.session.handle_timer(clock.now)
    warnings = sub.statuses()
    assert warnings == [
        {
            "op": "status",
            "level": "warning",
            "msg": "subscribe: /t missed its deadline: no message for 0.5 s",
            "id": "d",
        }
    ]
    _publish(pub, "b")  # the episode ends; a new silence is a new one
    for _ in range(10):
        clock.now += 0.2
        sub.session.handle_timer(clock.now)
    assert len(sub.statuses()) == 1


def test_the_topics_offered_deadline_warns_its_plain_subscribers(
    graph: Graph, clock: FakeClock
) -> None:
    pub = Peer(graph, "p")
    sub = Peer(graph, "s", level=StatusLevel.WARNING)
    pub.send(op="advertise", topic="/t", type=STRING, qos={"deadline": 1})
    sub.send(op="subscribe", topic="/t")  # as the web console subscribes
    for _ in range(5):
        _publish(pub, "steady")
        clock.now += 0.5
        sub.session.handle_timer(clock.now)
    assert sub.statuses() == []
    for _ in range(10):
        clock.now += 0.5
        sub.session.handle_timer(clock.now)
    [warning] = sub.statuses()
    assert warning["msg"] == "subscribe: /t missed its deadline: no message for 1 s"


def _silence(peer: Peer, clock: FakeClock, seconds: float) -> None:
    """``seconds`` pass without a message; the peer's timers run every 0.1 s."""
    for _ in range(round(seconds / 0.1)):
        clock.now += 0.1
        peer.session.handle_timer(clock.now)


def test_a_publisher_that_misses_its_offered_deadline_is_warned_once_per_episode(
    graph: Graph, clock: FakeClock
) -> None:
    pub = Peer(graph, "p", level=StatusLevel.WARNING)
    plain = Peer(graph, "q", level=StatusLevel.WARNING)
    pub.send(op="advertise", topic="/t", type=STRING, qos={"deadline": 0.5}, id="a")
    plain.send(op="advertise", topic="/t", type=STRING)  # asked no deadline: not told
    assert pub.statuses() == []
    _publish(pub, "a")
    _silence(pub, clock, 0.4)
    assert pub.statuses() == []
    _silence(pub, clock, 2.0)  # the deadline passed long ago: one warning for the silence
    assert pub.statuses() == [
        {
            "op": "status",
            "level": "warning",
            "msg": "advertise: /t missed its offered deadline: nothing published for 0.5 s",
            "id": "a",
        }
    ]
    _publish(plain, "b")  # anyone's message on the topic ends the episode
    _silence(pub, clock, 2.0)
    assert len(pub.statuses()) == 1
    assert plain.statuses() == []
    pub.send(op="unadvertise", topic="/t")
    _silence(pub, clock, 2.0)
    assert pub.statuses() == []  # no longer its offer


def test_a_publisher_is_warned_once_of_subscriptions_its_offer_cannot_meet(graph: Graph) -> None:
    pub = Peer(graph, "p", level=StatusLevel.WARNING)
    pub.send(op="advertise", topic="/scan", type=STRING, qos={"reliability": "best_effort"}, id=7)
    pub.statuses()
    first, second = Peer(graph, "s1"), Peer(graph, "s2")
    first.send(op="subscribe", topic="/scan", qos={"reliability": "reliable"})
    [warning] = pub.statuses()
    assert warning == {
        "op": "status",
        "level": "warning",
        "msg": "advertise: /scan offers keep_last 10, best_effort, volatile, which a subscription"
        " cannot use (reliability: reliable asked of a best_effort publisher): it receives"
        " nothing from this topic while that offer stands, as in ROS 2 (offered incompatible"
        " QoS)",
        "id": 7,
    }
    second.send(op="subscribe", topic="/scan", qos={"reliability": "reliable"})
    assert pub.statuses() == []  # the same episode
    first.send(op="unsubscribe", topic="/scan")
    second.send(op="unsubscribe", topic="/scan")
    second.send(op="subscribe", topic="/scan", qos={"durability": "transient_local"})
    [warning] = pub.statuses()  # a new episode
    assert "durability: transient_local asked of a volatile publisher" in str(warning["msg"])


def test_a_publisher_that_comes_after_a_subscription_it_cannot_meet_is_warned(
    graph: Graph,
) -> None:
    sub = Peer(graph, "s")
    sub.send(op="subscribe", topic="/scan", type=STRING, qos={"reliability": "reliable"})
    first, later = (
        Peer(graph, "p", level=StatusLevel.WARNING),
        Peer(graph, "q", StatusLevel.WARNING),
    )
    first.send(op="advertise", topic="/scan", type=STRING, qos={"reliability": "best_effort"})
    later.send(op="advertise", topic="/scan", type=STRING, qos={"reliability": "best_effort"})
    for peer in (first, later):  # each publisher that offers it, once
        [warning] = peer.statuses()
        assert "(offered incompatible QoS)" in str(warning["msg"])
