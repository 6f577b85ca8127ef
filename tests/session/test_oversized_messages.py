"""A topic message larger than the send buffer limit (D24, docs/limits.md).

It goes out through an empty outbox, held alone; while it waits, the outbox
counts as full, so what it holds stays within the limit plus that one message.
Where other topic messages wait, it is dropped and the subscriber is told, once,
with a warning naming ``--send-buffer-limit``. Its frames are the ones every
subscriber shares: nothing is copied per connection.
"""

from __future__ import annotations

import json

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.outbox import Outbox, OutFrame
from rwt_protocol.server.session import Session, SessionConfig

LIMIT = 64 * 1024
BIG = 5 * LIMIT  # characters of one message's data: five times the limit


def subscriber(graph: Graph, name: str, timeout_s: float = 30.0) -> Session:
    session = Session(
        graph.port,
        name,
        config=SessionConfig(
            send_buffer_limit=LIMIT, send_timeout_s=timeout_s, status_level=StatusLevel.WARNING
        ),
    )
    for topic in ("/big", "/small"):
        op = {"op": "subscribe", "topic": topic, "type": "std_msgs/String"}
        session.receive_frame(json.dumps(op), 0.0)
    return session


def decoded(session: Session) -> list[dict[str, object]]:
    return [json.loads(frame.data) for frame in session.frames_to_send()]


def big(tag: str) -> dict[str, str]:
    return {"data": tag + "x" * BIG}


def test_a_message_over_the_limit_reaches_an_idle_subscriber_and_no_status(graph: Graph) -> None:
    session = subscriber(graph, "sub")
    publisher = graph.create_publisher("/big", "std_msgs/msg/String")
    publisher.publish(big("a"))
    assert session.stats.queued_bytes > LIMIT  # held alone, past the limit
    assert decoded(session) == [{"op": "publish", "topic": "/big", "msg": big("a")}]
    publisher.publish(big("b"))  # the outbox is empty again: the next one goes too
    assert decoded(session) == [{"op": "publish", "topic": "/big", "msg": big("b")}]
    assert session.stats.dropped_frames == 0


def test_queued_bytes_never_exceed_the_limit_plus_one_message(graph: Graph) -> None:
    session = subscriber(graph, "sub")
    big_topic = graph.create_publisher("/big", "std_msgs/msg/String")
    small_topic = graph.create_publisher("/small", "std_msgs/msg/String")
    big_topic.publish(big("first"))
    message = session.stats.queued_bytes  # one message's charge: its payload and overhead
    assert message > LIMIT
    most, received = 0, []
    for i in range(300):  # a subscriber that reads less than comes, catching up now and then
        big_topic.publish(big(f"{i:03d}"))
        most = max(most, session.stats.queued_bytes)
        for _ in range(3):
            small_topic.publish({"data": f"{i:03d}" + "y" * 2000})
            most = max(most, session.stats.queued_bytes)
        if i % 10 == 9:
            received += decoded(session)
        elif i % 4 == 0:
            received += [json.loads(f.data) for f in session.frames_to_send(LIMIT // 2)]
    assert most <= LIMIT + message
    received += decoded(session)
    bigs = [m for m in received if m.get("topic") == "/big"]
    assert bigs[0]["msg"] == big("first") and len(bigs) > 1  # more went out, each whole
    assert all(len(m["msg"]["data"]) == BIG + 3 for m in bigs[1:])
    texts = [str(m["msg"]) for m in received if m["op"] == "status"]
    assert any("dropping the oldest topic messages" in text for text in texts), texts


def test_one_that_comes_while_others_wait_is_dropped_with_a_status_naming_the_option(
    graph: Graph,
) -> None:
    session = subscriber(graph, "sub")
    big_topic = graph.create_publisher("/big", "std_msgs/msg/String")
    small_topic = graph.create_publisher("/small", "std_msgs/msg/String")
    small_topic.publish({"data": "s1"})
    big_topic.publish(big("a"))  # the subscriber has not taken s1: it is behind
    big_topic.publish(big("b"))
    small_topic.publish({"data": "s2"})
    messages = decoded(session)
    assert [m["op"] for m in messages] == ["publish", "status", "publish"]
    assert messages[1]["level"] == "warning"
    text = str(messages[1]["msg"])
    assert "--send-buffer-limit 65536 bytes" in text and "/big" in text, text
    assert [m["msg"] for m in messages if m["op"] == "publish"] == [{"data": "s1"}, {"data": "s2"}]
    assert session.stats.dropped_frames == 2
    big_topic.publish(big("c"))  # not behind any more: it goes out
    assert decoded(session) == [{"op": "publish", "topic": "/big", "msg": big("c")}]


def test_the_status_is_sent_once_until_such_a_message_went_out_again(graph: Graph) -> None:
    session = subscriber(graph, "sub")
    big_topic = graph.create_publisher("/big", "std_msgs/msg/String")
    small_topic = graph.create_publisher("/small", "std_msgs/msg/String")

    def behind_then_dropped() -> list[str]:
        texts = []
        for i in range(3):
            small_topic.publish({"data": f"s{i}"})
            big_topic.publish(big(f"{i}"))
            texts += [str(m["msg"]) for m in decoded(session) if m["op"] == "status"]
        return texts

    assert len(behind_then_dropped()) == 1  # three drops, one status
    assert behind_then_dropped() == []  # still none went out: not told again
    big_topic.publish(big("through"))
    assert [m["msg"] for m in decoded(session)] == [big("through")]
    assert len(behind_then_dropped()) == 1  # a new episode


def test_a_subscriber_that_stays_behind_and_takes_nothing_is_closed(graph: Graph) -> None:
    session = subscriber(graph, "stalled", timeout_s=1.0)
    big_topic = graph.create_publisher("/big", "std_msgs/msg/String")
    small_topic = graph.create_publisher("/small", "std_msgs/msg/String")
    small_topic.publish({"data": "s"})
    big_topic.publish(big("a"))
    session.handle_timer(session.now + 2.0)
    assert session.close_request is not None
    assert "slow consumer" in session.close_request.reason


def test_an_idle_subscriber_holding_one_is_not_closed(graph: Graph) -> None:
    session = subscriber(graph, "idle", timeout_s=1.0)
    graph.create_publisher("/big", "std_msgs/msg/String").publish(big("a"))
    session.handle_timer(session.now + 5.0)
    assert session.close_request is None
    assert [m["msg"] for m in decoded(session)] == [big("a")]


def test_every_subscriber_gets_the_same_frame_not_a_copy(graph: Graph) -> None:
    sessions = [subscriber(graph, f"s{i}") for i in range(5)]
    graph.create_publisher("/big", "std_msgs/msg/String").publish(big("a"))
    frames = [session.frames_to_send() for session in sessions]
    assert all(len(taken) == 1 for taken in frames)
    first = frames[0][0]
    assert all(taken[0] is first and taken[0].data is first.data for taken in frames)
    assert len(first.data) > LIMIT


def test_fragmented_parts_over_the_limit_are_held_together() -> None:
    box = Outbox(limit_bytes=10, frame_overhead_bytes=0)
    group = object()
    parts = [OutFrame(b"aaaa", droppable=True, group=group) for _ in range(4)]
    box.extend(parts)
    assert box.queued_bytes == 16 and box.held_bytes == 16 and not box.over_limit
    box.push(OutFrame(b"late", droppable=True))  # full: dropped on arrival
    box.push(OutFrame(b"st"))  # a status is never dropped
    assert [f.data for f in box.take(max_bytes=8)] == [b"aaaa", b"aaaa"]
    assert box.held_bytes == 8
    assert [f.data for f in box.drain()] == [b"aaaa", b"aaaa", b"st"]
    assert box.held_bytes == 0 and box.queued_bytes == 0 and box.dropped == 1
    box.push(OutFrame(b"bbbbbbbbbbbb", droppable=True))  # empty again: held
    assert box.held_bytes == 12


def test_the_outbox_counts_topic_messages_queued_dropped_and_frames_taken() -> None:
    """The counts behind a connection's ``event=disconnect`` line add up (docs/server.md)."""
    box = Outbox(limit_bytes=1000, frame_overhead_bytes=0)
    for _ in range(30):
        box.push(OutFrame(b"x" * 100, droppable=True))
    box.push(OutFrame(b"reply"))  # never dropped, never a topic message
    taken = box.take()
    assert box.topic_messages == 30
    assert 0 < box.dropped < 30
    assert box.taken_frames == len(taken)
    assert box.topic_messages - box.dropped == sum(frame.droppable for frame in taken)
