"""Topic ops through two sessions on one graph (spec 3.3.1-3.3.5, D1-D3, D7, D11, D13, D26)."""

from __future__ import annotations

import json

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.server.session import Session, SessionConfig
from tests.conftest import Peer


def test_publish_reaches_a_subscriber_on_another_connection(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    a.send(op="advertise", topic="/chatter", type="std_msgs/String")
    b.send(op="subscribe", topic="/chatter", type="std_msgs/msg/String")
    a.send(op="publish", topic="/chatter", msg={"data": "hello"})
    assert b.received() == [{"op": "publish", "topic": "/chatter", "msg": {"data": "hello"}}]
    assert a.received() == []


def test_subscriber_gets_its_own_spelling_of_the_topic(graph: Graph) -> None:
    a, b, c = Peer(graph, "a"), Peer(graph, "b"), Peer(graph, "c")
    a.send(op="advertise", topic="chatter", type="std_msgs/String")
    b.send(op="subscribe", topic="chatter")
    c.send(op="subscribe", topic="/chatter")
    a.send(op="publish", topic="/chatter", msg={"data": "x"})
    assert b.received()[0]["topic"] == "chatter"
    assert c.received()[0]["topic"] == "/chatter"


def test_one_message_is_encoded_once_for_all_subscribers(graph: Graph) -> None:
    a = Peer(graph, "a")
    subscribers = [Peer(graph, f"s{i}") for i in range(5)]
    a.send(op="advertise", topic="/t", type="std_msgs/String")
    for peer in subscribers:
        peer.send(op="subscribe", topic="/t")
    a.send(op="publish", topic="/t", msg={"data": "once"})
    frames = [peer.session.frames_to_send()[0].data for peer in subscribers]
    assert all(frame is frames[0] for frame in frames)


def test_type_conflict_is_an_error_status_with_the_id(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    a.send(op="advertise", topic="/t", type="std_msgs/String")
    b.send(op="advertise", topic="/t", type="std_msgs/Int32", id="adv-1")
    [status] = b.statuses()
    assert status["level"] == "error"
    assert status["id"] == "adv-1"
    assert str(status["msg"]).startswith("advertise: ")
    assert "std_msgs/msg/String" in str(status["msg"])


def test_subscribe_without_type_to_an_unknown_topic_fails(peers: tuple[Peer, Peer]) -> None:
    a, _ = peers
    a.send(op="subscribe", topic="/nobody", id=4)
    [status] = a.statuses()
    assert status["id"] == 4
    assert "subscribe: " in str(status["msg"])


def test_subscribe_with_type_waits_for_publishers(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    b.send(op="subscribe", topic="/later", type="std_msgs/Int32")
    a.send(op="publish", topic="/later", msg={"data": 3})
    assert b.received() == [{"op": "publish", "topic": "/later", "msg": {"data": 3}}]


def test_publish_to_a_topic_without_type_is_an_error(peers: tuple[Peer, Peer]) -> None:
    a, _ = peers
    a.send(op="publish", topic="/void", msg={"data": 1}, id="p")
    [status] = a.statuses()
    assert status["level"] == "error" and status["id"] == "p"


def test_invalid_message_is_rejected_with_its_path_and_not_delivered(
    peers: tuple[Peer, Peer],
) -> None:
    a, b = peers
    a.send(op="advertise", topic="/t", type="std_msgs/String")
    b.send(op="subscribe", topic="/t")
    a.send(op="publish", topic="/t", msg={"data": 5})
    [status] = a.statuses()
    assert "$.msg.data" in str(status["msg"])
    assert str(status["msg"]).startswith("publish: ")
    assert b.received() == []


def test_partial_message_gets_defaults_and_a_warning_when_asked(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    a.send(op="set_level", level="warning")
    a.send(op="advertise", topic="/cmd", type="geometry_msgs/Twist")
    b.send(op="subscribe", topic="/cmd")
    a.send(op="publish", topic="/cmd", msg={"linear": {"x": 1.5}}, id="p1")
    [delivered] = b.received()
    assert delivered["msg"] == {
        "linear": {"x": 1.5, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 0.0},
    }
    [warning] = a.statuses()
    assert warning["level"] == "warning" and warning["id"] == "p1"
    assert "$.msg.angular" in str(warning["msg"])


def test_default_level_hides_warnings_and_successes(peers: tuple[Peer, Peer]) -> None:
    a, _ = peers
    a.send(op="advertise", topic="/cmd", type="geometry_msgs/Twist")
    a.send(op="publish", topic="/cmd", msg={})
    assert a.received() == []


def test_info_level_reports_successes(graph: Graph) -> None:
    a = Peer(graph, "a", level=StatusLevel.INFO)
    a.send(op="advertise", topic="/t", type="std_msgs/String", id="x")
    [status] = a.statuses()
    assert status == {"op": "status", "level": "info", "msg": status["msg"], "id": "x"}


def test_level_none_silences_even_errors(peers: tuple[Peer, Peer]) -> None:
    a, _ = peers
    a.send(op="set_level", level="none")
    a.send(op="nonsense")
    a.send_raw("garbage")
    assert a.received() == []


def test_bad_set_level_keeps_the_level(peers: tuple[Peer, Peer]) -> None:
    a, _ = peers
    a.send(op="set_level", level="loud")
    assert [s["level"] for s in a.statuses()] == ["error"]
    assert a.session.status_level is StatusLevel.ERROR


def test_two_subscriptions_of_one_client_deliver_one_copy(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    a.send(op="advertise", topic="/t", type="std_msgs/String")
    b.send(op="subscribe", topic="/t", id="one")
    b.send(op="subscribe", topic="/t", id="two")
    a.send(op="publish", topic="/t", msg={"data": "x"})
    assert len(b.received()) == 1


def test_unsubscribe_by_id_removes_only_that_id(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    a.send(op="advertise", topic="/t", type="std_msgs/String")
    b.send(op="subscribe", topic="/t", id="one")
    b.send(op="subscribe", topic="/t", id="two")
    b.send(op="unsubscribe", topic="/t", id="one")
    a.send(op="publish", topic="/t", msg={"data": "still"})
    assert [m["op"] for m in b.received()] == ["publish"]
    b.send(op="unsubscribe", topic="/t", id="two")
    a.send(op="publish", topic="/t", msg={"data": "gone"})
    assert b.received() == []


def test_unsubscribe_with_an_unknown_id_warns_and_keeps_the_subscription(graph: Graph) -> None:
    a, b = Peer(graph, "a"), Peer(graph, "b", level=StatusLevel.WARNING)
    a.send(op="advertise", topic="/t", type="std_msgs/String")
    b.send(op="subscribe", topic="/t")
    b.send(op="unsubscribe", topic="/t", id="nope")
    assert [s["level"] for s in b.statuses()] == ["warning"]
    a.send(op="publish", topic="/t", msg={"data": "x"})
    assert len(b.received()) == 1


def test_unadvertise_of_a_topic_not_advertised_warns(graph: Graph) -> None:
    a = Peer(graph, "a", level=StatusLevel.WARNING)
    a.send(op="unadvertise", topic="/never")
    [status] = a.statuses()
    assert status["level"] == "warning"


def test_last_unadvertise_and_unsubscribe_remove_the_topic(
    graph: Graph, peers: tuple[Peer, Peer]
) -> None:
    a, b = peers
    a.send(op="advertise", topic="/t", type="std_msgs/String", id=1)
    a.send(op="advertise", topic="/t", type="std_msgs/String", id=2)
    b.send(op="subscribe", topic="/t")
    a.send(op="unadvertise", topic="/t", id=1)
    assert "/t" in dict(graph.topic_names_and_types())
    a.send(op="unadvertise", topic="/t", id=2)
    b.send(op="unsubscribe", topic="/t")
    assert "/t" not in dict(graph.topic_names_and_types())


def test_disconnect_releases_everything(graph: Graph) -> None:
    a = Peer(graph, "a")
    a.send(op="advertise", topic="/t1", type="std_msgs/String")
    a.send(op="subscribe", topic="/t2", type="std_msgs/String")
    a.session.close()
    assert graph.topic_names_and_types() == [
        (name, t) for name, t in graph.topic_names_and_types() if name not in ("/t1", "/t2")
    ]
    assert "/t1" not in dict(graph.topic_names_and_types())


def test_latched_message_reaches_each_later_subscriber_once(graph: Graph) -> None:
    a = Peer(graph, "a")
    a.send(op="advertise", topic="/map", type="std_msgs/String", latch=True)
    a.send(op="publish", topic="/map", msg={"data": "the map"})
    for name in ("x", "y", "z"):
        late = Peer(graph, name)
        late.send(op="subscribe", topic="/map")
        late.send(op="subscribe", topic="/map", id="again")
        assert [m["msg"] for m in late.received()] == [{"data": "the map"}]


def test_bad_frames_never_stop_the_connection_or_touch_others(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    b.send(op="subscribe", topic="/t", type="std_msgs/String")
    garbage = [
        "not json",
        "5",
        '"op"',
        '"valid"',
        '["id", "op"]',
        "null",
        "true",
        "{}",
        '{"op": ["x"]}',
        '{"op": {"k": 1}}',
        '{"op": "nope"}',
        '{"op": "subscribe"}',
        '{"png": 1}',
        '{"op": "publish", "topic": "/t", "msg": "text"}',
        b"\xff\xfe",
        '{"op": "subscribe", "topic": "/t", "fragment_size": -1}',
    ]
    for frame in garbage:
        a.send_raw(frame)
    statuses = a.statuses()
    assert len(statuses) == len(garbage)
    assert all(s["level"] == "error" for s in statuses)
    assert all("Traceback" not in str(s["msg"]) for s in statuses)
    a.send(op="publish", topic="/t", msg={"data": "after"})
    assert b.received() == [{"op": "publish", "topic": "/t", "msg": {"data": "after"}}]


def test_status_goes_only_to_the_connection_that_caused_it(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    a.send(op="nope")
    assert len(a.statuses()) == 1
    assert b.received() == []


def test_slow_peer_loses_oldest_topic_messages_never_statuses(graph: Graph) -> None:
    a = Peer(graph, "a")
    slow = Session(graph.port, "slow", config=SessionConfig(send_buffer_limit=2000))
    a.send(op="advertise", topic="/t", type="std_msgs/String")
    slow.receive_frame(json.dumps({"op": "subscribe", "topic": "/t"}), 0.0)
    slow.receive_frame('{"op": "bad"}', 0.0)
    for i in range(100):
        a.send(op="publish", topic="/t", msg={"data": f"{i:04d}" + "x" * 100})
    frames = [json.loads(f.data) for f in slow.frames_to_send()]
    assert frames[0]["op"] == "status"
    data = [f["msg"]["data"][:4] for f in frames[1:]]
    assert data[-1] == "0099"
    assert data == sorted(data)
    assert len(data) < 100
    assert slow.stats.dropped_frames == 100 - len(data)


def test_in_process_publisher_and_subscriber_meet_clients(graph: Graph) -> None:
    seen: list[dict[str, object]] = []
    graph.create_subscription("/cmd", seen.append, "geometry_msgs/msg/Twist")
    a = Peer(graph, "a")
    a.send(op="publish", topic="cmd", msg={"angular": {"z": 0.5}})
    assert seen[0]["angular"] == {"x": 0.0, "y": 0.0, "z": 0.5}
    b = Peer(graph, "b")
    b.send(op="subscribe", topic="/odom_count", type="std_msgs/Int32")
    graph.create_publisher("/odom_count", "std_msgs/Int32").publish({"data": 7})
    assert b.received() == [{"op": "publish", "topic": "/odom_count", "msg": {"data": 7}}]


def test_a_validated_local_publish_sends_what_the_checked_one_sends(graph: Graph) -> None:
    subscriber = Peer(graph, "b")
    subscriber.send(op="subscribe", topic="/pose", type="geometry_msgs/msg/PoseStamped")
    publisher = graph.create_publisher("/pose", "geometry_msgs/msg/PoseStamped")
    given = {"header": {"frame_id": "map"}, "pose": {"position": {"x": 1, "y": -2.5}}}
    publisher.publish(given)
    internal = publisher.msgtype.from_python(given, now=graph.clock.wall())
    publisher.publish(internal, validated=True)
    checked, trusted = (frame.data for frame in subscriber.session.frames_to_send())
    assert trusted == checked
    assert json.loads(checked)["msg"]["pose"]["position"] == {"x": 1.0, "y": -2.5, "z": 0.0}


def test_a_type_a_link_cannot_carry_gets_a_warning_and_the_op_stands(graph: Graph) -> None:
    graph.type_checks.append(
        lambda name: None if name == "std_msgs/msg/String" else f"no package for {name}"
    )
    a, b = Peer(graph, "a"), Peer(graph, "b")
    a.send(op="set_level", level="warning")
    a.send(op="advertise", topic="/ok", type="std_msgs/String", id="a0")
    a.send(op="advertise", topic="/n", type="std_msgs/Int32", id="a1")
    a.send(op="subscribe", topic="/m", type="std_msgs/Float64", id="s1")
    a.send(op="advertise_service", service="/srv", type="std_srvs/SetBool")
    a.send(op="advertise_action", action="/fib", type="example_interfaces/action/Fibonacci")
    texts = [(s["level"], s.get("id"), s["msg"]) for s in a.statuses()]
    assert texts == [
        ("warning", "a1", "advertise: no package for std_msgs/msg/Int32"),
        ("warning", "s1", "subscribe: no package for std_msgs/msg/Float64"),
        ("warning", None, "advertise_service: no package for std_srvs/srv/SetBool"),
        ("warning", None, "advertise_action: no package for example_interfaces/action/Fibonacci"),
    ]
    b.send(op="publish", topic="/n", msg={"data": 1})  # the topic stands in the graph
    assert b.statuses() == []
