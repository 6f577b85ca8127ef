"""A subscriber's queue holds at most a lifespan's worth of a topic's ROS 2 samples.

A sample from ROS 2 comes with a lifespan (``rwt_ros2.link.SAMPLE_LIFESPAN_S``):
a reader that falls behind a steady stream gets the newest samples and a drop
count, not old ones, while a burst that came within the lifespan reaches it
whole, and messages without one (a rosbridge client's, replies) are bounded by
bytes alone (docs/ros2.md, "Latency under rate"). Driven by hand-moved time: no
test here waits.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hypothesis import given
from hypothesis import strategies as st

from rwt_graph.link import LinkRules, Relays
from rwt_protocol.runtime.outbox import Outbox, OutFrame
from rwt_ros2.link import SAMPLE_LIFESPAN_S

if TYPE_CHECKING:
    from rwt_graph import Graph
    from rwt_graph.topics import Topic

    from ..conftest import FakeClock, Peer

STRING = "std_msgs/msg/String"
LIFESPAN = 0.0195  # 19.5 ms: 20 messages 1 ms apart, the newest included
BIG = 1 << 30  # no byte bound in play


def _frame(text: str) -> OutFrame:
    return OutFrame(text.encode(), droppable=True)


def _texts(frames: list[OutFrame]) -> list[str]:
    return [frame.data.decode() for frame in frames]


def test_a_reader_behind_a_steady_stream_gets_the_newest_not_old_ones() -> None:
    box = Outbox(limit_bytes=BIG)
    for i in range(1000):  # 1 kHz for 1 s, and the reader reads nothing
        box.extend([_frame(f"m{i}")], 100 + i / 1000, LIFESPAN, "/fast")
        assert len(box) <= 20  # never more than the lifespan's worth
    assert _texts(box.take()) == [f"m{i}" for i in range(980, 1000)]
    assert box.dropped == box.expired == 980
    assert box.topic_messages == 1000


def test_a_burst_within_the_lifespan_reaches_a_slow_reader_whole() -> None:
    box = Outbox(limit_bytes=BIG)
    for i in range(500):  # one burst: the same moment
        box.extend([_frame(f"b{i}")], 100.0, LIFESPAN, "/burst")
    box.extend([_frame("later")], 100.0 + LIFESPAN / 2, LIFESPAN, "/burst")
    assert _texts(box.take()) == [f"b{i}" for i in range(500)] + ["later"]
    assert box.dropped == 0


def test_messages_without_a_lifespan_are_bounded_by_bytes_alone() -> None:
    box = Outbox(limit_bytes=BIG)
    for i in range(1000):  # a rosbridge client's publishes, paced by input backpressure
        box.extend([_frame(f"c{i}")], 100 + i / 1000)
    box.push(OutFrame(b"reply"))
    assert _texts(box.take()) == [f"c{i}" for i in range(1000)] + ["reply"]
    assert box.dropped == box.expired == 0


def test_one_topic_waiting_at_the_head_does_not_shield_another_topics_backlog() -> None:
    box = Outbox(limit_bytes=BIG)
    box.extend([_frame("slow")], 100.0, LIFESPAN, "/slow")  # its only message: it stays
    box.push(OutFrame(b"reply"))
    for i in range(300):
        box.extend([_frame(f"f{i}")], 100 + i / 1000, LIFESPAN, "/fast")
    assert _texts(box.take()) == ["slow", "reply"] + [f"f{i}" for i in range(280, 300)]
    assert box.expired == 280


def test_a_fragmented_sample_goes_whole_or_not_at_all() -> None:
    box = Outbox(limit_bytes=BIG)
    for i in range(30):
        parts = [OutFrame(f"p{i}.{k}".encode(), droppable=True, group=i) for k in range(3)]
        box.extend(parts, 100 + i / 1000, LIFESPAN, "/cloud")
    assert _texts(box.take()) == [f"p{i}.{k}" for i in range(10, 30) for k in range(3)]
    assert box.expired == 10


def test_a_message_partly_sent_is_never_cut() -> None:
    box = Outbox(limit_bytes=BIG)
    parts = [OutFrame(f"first.{k}".encode(), droppable=True, group="g") for k in range(3)]
    box.extend(parts, 100.0, LIFESPAN, "/cloud")
    assert _texts(box.take(1)) == ["first.0"]  # the writer has begun it
    for i in range(30):  # it is long outdated now, but its rest must follow
        box.extend([_frame(f"n{i}")], 101 + i / 1000, LIFESPAN, "/cloud")
    assert _texts(box.take()) == ["first.1", "first.2"] + [f"n{i}" for i in range(10, 30)]


# One push: (topic or None for no lifespan, ms after the previous push, size); or a take
# of about so many payload bytes.
OPS = st.lists(
    st.one_of(
        st.tuples(st.sampled_from(["/a", "/b", None]), st.integers(0, 15), st.integers(1, 40)),
        st.integers(1, 200),
    ),
    max_size=120,
)


@given(OPS)
def test_the_queue_is_the_stream_less_what_newer_samples_outdated(
    ops: list[tuple[str | None, int, int] | int],
) -> None:
    """Against a model: a take gets the oldest frames the model still holds, in order."""
    box = Outbox(limit_bytes=BIG, frame_overhead_bytes=16)
    model: list[tuple[str | None, float, bytes]] = []  # what should be queued, in order
    now, serial = 100.0, 0
    for op in ops:
        if isinstance(op, int):
            taken = box.take(op)
            want, size = [], 0
            while model and (not want or size + len(model[0][2]) <= op):
                size += len(model[0][2])
                want.append(model.pop(0)[2])
            assert [frame.data for frame in taken] == want
            continue
        topic, gap_ms, size = op
        now += gap_ms / 1000
        data = f"{serial}:".encode().ljust(size, b"x")
        serial += 1
        if topic is None:
            box.extend([OutFrame(data, droppable=True)], now)
        else:
            box.extend([OutFrame(data, droppable=True)], now, LIFESPAN, topic)
            model = [m for m in model if m[0] != topic or now - m[1] <= LIFESPAN]
        model.append((topic, now, data))
        assert len(box) == len(model)
        assert box.queued_bytes == sum(len(m[2]) + 16 for m in model)
    assert [frame.data for frame in box.take()] == [m[2] for m in model]


def _relayed(graph: Graph) -> tuple[Relays, Topic]:
    """The relays of a ROS 2 link on ``graph`` and the entry of ``/fast`` (subscribed)."""
    return Relays(graph, LinkRules("ros2:"), "/rwt", lambda _gid: None), graph.topics["/fast"]


def test_a_subscriber_that_does_not_read_gets_the_newest_samples_and_a_drop_count(
    graph: Graph, clock: FakeClock, peers: tuple[Peer, Peer]
) -> None:
    _, reader = peers
    reader.send(op="subscribe", topic="/fast", type=STRING)
    reader.received()
    relays, entry = _relayed(graph)
    for i in range(200):  # a 1 kHz ROS 2 topic, as the link publishes it, unread
        clock.now += 0.001
        relays.deliver(entry, None, {"data": f"s{i}"}, lifespan=SAMPLE_LIFESPAN_S)
    got = [m["msg"]["data"] for m in reader.received() if m["op"] == "publish"]  # type: ignore[index]
    kept = int(SAMPLE_LIFESPAN_S * 1000)  # within 20 ms of the newest: about 20
    assert got[-1] == "s199"  # the newest always
    assert kept - 1 <= len(got) <= kept + 1
    assert got == [f"s{i}" for i in range(200 - len(got), 200)]  # the newest, in order
    assert (
        reader.session.stats.expired_messages
        == reader.session.stats.dropped_frames
        == 200 - len(got)
    )


def test_a_rosbridge_publishers_messages_are_not_cut_by_time(
    clock: FakeClock, peers: tuple[Peer, Peer]
) -> None:
    writer, reader = peers
    reader.send(op="subscribe", topic="/chat", type=STRING)
    writer.send(op="advertise", topic="/chat", type=STRING)
    reader.received()
    for i in range(200):
        clock.now += 0.001
        writer.send(op="publish", topic="/chat", msg={"data": f"c{i}"})
    got = [m["msg"]["data"] for m in reader.received() if m["op"] == "publish"]  # type: ignore[index]
    assert got == [f"c{i}" for i in range(200)]
    assert reader.session.stats.dropped_frames == 0
