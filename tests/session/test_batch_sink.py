"""A rosbridge subscription takes a run of messages in one call, as it takes them one by one.

``rosbridge-batch-sink`` (rwt_protocol.shortcuts): a run of a topic's messages (a
ROS 2 link's samples, a turn's batch of a publisher's) reaches a rosbridge
subscription in one call, and its session queues each one-frame message in the
fewest steps (``Session.deliver_many``, ``Outbox.push_timed``). What the peer
gets must be what the general path (``TopicSubscription``, message by message,
``Outbox.extend``) gives it: the same frames in the same order, the same drops
and expiries under a small send buffer, the same throttling. Driven by
hand-moved time: no test here waits.
"""

from __future__ import annotations

import json
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rwt_graph.graph import Graph
from rwt_graph.types import codec_for
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.commands import CloseCode
from rwt_protocol.runtime.outbox import Outbox, OutFrame
from rwt_protocol.server.handlers import topics as topic_handlers
from rwt_protocol.server.session import Session, SessionConfig
from rwt_protocol.server.subscriptions import BatchTopicSubscription

from ..conftest import FakeClock

STRING = "std_msgs/msg/String"
LIFESPAN = 0.0095  # about ten 1 ms samples


def _cdr(text: str) -> bytes:
    """``std_msgs/msg/String`` as rclpy serializes it (little-endian CDR)."""
    data = text.encode() + b"\0"
    return b"\0\1\0\0" + len(data).to_bytes(4, "little") + data + b"\0" * (-len(data) % 4)


# ---- the queue: push_timed is extend of one frame ------------------------------------

# One op: push a topic message (topic, ms after the previous, size, with a lifespan),
# push a reply (None), or take about so many payload bytes (an int).
QUEUE_OPS = st.lists(
    st.one_of(
        st.tuples(
            st.sampled_from(["/a", "/b"]), st.integers(0, 6), st.integers(1, 400), st.booleans()
        ),
        st.none(),
        st.integers(1, 900),
    ),
    max_size=150,
)


def _state(box: Outbox) -> tuple[int, ...]:
    return (
        len(box),
        box.queued_bytes,
        box.dropped,
        box.expired,
        box.dropped_oversized,
        box.held_bytes,
        box.topic_frames,
        box.topic_messages,
    )


@given(QUEUE_OPS, st.sampled_from([None, 5]))
def test_the_hot_paths_queue_and_drop_as_extend_does(
    ops: list[tuple[str, int, int, bool] | int | None], max_messages: int | None
) -> None:
    # a limit a few messages fill, so shedding, holding an oversized message and
    # dropping it all happen
    fast = Outbox(limit_bytes=1200, frame_overhead_bytes=16, max_messages=max_messages)
    general = Outbox(limit_bytes=1200, frame_overhead_bytes=16, max_messages=max_messages)
    now = 100.0
    for serial, op in enumerate(ops):
        if isinstance(op, int):
            assert [f.data for f in fast.take(op)] == [f.data for f in general.take(op)]
        elif op is None:
            reply = OutFrame(f"reply{serial}".encode())
            fast.push(reply)
            general.push(reply)
        else:
            topic, gap_ms, size, timed = op
            now += gap_ms / 1000
            frame = OutFrame(f"{serial}:".encode().ljust(size, b"x"), droppable=True)
            if timed:
                fast.push_timed(frame, now, LIFESPAN, topic)
                general.extend([frame], now, LIFESPAN, topic)
            else:
                fast.push_droppable(frame)
                general.extend([frame], now)
        assert _state(fast) == _state(general)
    assert [f.data for f in fast.take()] == [f.data for f in general.take()]


# ---- the session: a run reaches the peer as its messages one by one would --------------


class Side:
    """A graph with a local publisher of ``/t`` and one peer subscribed to it."""

    def __init__(self, batch: bool, subscribe: dict[str, Any], limit: int) -> None:
        self.clock = FakeClock()
        self.graph = Graph(clock=self.clock)
        config = SessionConfig(send_buffer_limit=limit, status_level=StatusLevel.WARNING)
        self.session = Session(self.graph.port, "peer", config=config)
        chosen, topic_handlers._BATCH_SINK = topic_handlers._BATCH_SINK, batch
        try:  # the handler makes the subscription of the kind asked for
            self.session.receive_frame(
                json.dumps({"op": "subscribe", "topic": "/t", "type": STRING, **subscribe}),
                self.clock.now,
            )
        finally:
            topic_handlers._BATCH_SINK = chosen
        [subscription] = self.session.holdings.subscriptions.values()
        assert isinstance(subscription, BatchTopicSubscription) is batch
        self.graph.port.advertise("pub", "/t", STRING)
        self.frames: list[tuple[bool, bytes | str]] = []

    def publish(self, texts: list[str], gap_ms: int, lifespan: float) -> None:
        self.clock.now += gap_ms / 1000
        self.graph.port.publish_local_many(
            "pub", "/t", [None] * len(texts), [_cdr(t) for t in texts], lifespan
        )

    def tick(self, ms: int) -> None:
        self.clock.now += ms / 1000
        due = self.session.get_timer()
        while due is not None and due <= self.clock.now:
            self.session.handle_timer(self.clock.now)
            due = self.session.get_timer()

    def read(self, max_bytes: int | None) -> None:
        for frame in self.session.frames_to_send(max_bytes):
            self.frames.append((frame.binary, _without_fragment_ids(frame.data)))


def _without_fragment_ids(data: bytes) -> bytes | str:
    """A frame, the id of a fragment aside (each message's parts are numbered apart)."""
    if data[:1] != b"{":
        return data
    op = json.loads(data)
    if "num" in op:  # a part of a fragmented message (``fragment`` or ``png``)
        op["id"] = "part"
    return json.dumps(op, sort_keys=True)


SUBSCRIBE = st.fixed_dictionaries(
    {
        "compression": st.sampled_from(["none", "cbor", "cbor-raw", "png"]),
        "fragment_size": st.sampled_from([None, None, 70]),
        "throttle_rate": st.sampled_from([0, 0, 4]),
        "queue_length": st.sampled_from([0, 3]),
    }
)
# One step: publish a run (messages, ms after the previous step, with a lifespan, one
# of them larger than the small send buffer), let time pass (ms, for a throttle's
# windows), or read about so many bytes (None: all).
STEPS = st.lists(
    st.one_of(
        st.tuples(st.integers(1, 12), st.integers(0, 6), st.booleans(), st.booleans()),
        st.integers(1, 8),
        st.sampled_from([None, 300, 2000]),
    ),
    max_size=25,
)


@settings(max_examples=50)  # two graphs and sessions an example: the suite's time
@given(SUBSCRIBE, STEPS, st.sampled_from([1 << 20, 2500]))
def test_a_run_reaches_the_peer_as_its_messages_one_by_one(
    subscribe: dict[str, Any],
    steps: list[tuple[int, int, bool, bool] | int | None],
    limit: int,
) -> None:
    sides = [Side(batch, subscribe, limit) for batch in (True, False)]
    serial = 0
    for step in steps:
        if isinstance(step, tuple):
            count, gap_ms, timed, big = step
            texts = [f"m{serial + i}" for i in range(count)]
            if big:  # over the small limit: held alone, or dropped
                texts[-1] = texts[-1].ljust(3000, "x")
            serial += count
            for side in sides:
                side.publish(texts, gap_ms, LIFESPAN if timed else 0.0)
        elif isinstance(step, int) and step <= 8:
            for side in sides:
                side.tick(step)
        else:
            for side in sides:
                side.read(step)
    for side in sides:
        side.tick(50)
        side.read(None)
    fast, general = sides
    assert fast.frames == general.frames
    assert fast.session.stats.dropped_frames == general.session.stats.dropped_frames
    assert fast.session.stats.expired_messages == general.session.stats.expired_messages
    for side in sides:
        side.session.close()


def test_a_run_to_an_unthrottled_subscription_is_one_call_and_one_wake() -> None:
    side = Side(True, {}, 1 << 20)
    side.read(None)  # (the subscribe's own output, if any)
    wakes: list[None] = []
    side.session._on_output = lambda: wakes.append(None)
    side.publish([f"m{i}" for i in range(50)], 1, LIFESPAN)
    assert len(wakes) == 1
    side.read(None)
    texts = [json.loads(data)["msg"]["data"] for _, data in side.frames]
    assert texts == [f"m{i}" for i in range(50)]
    side.session.close()


def test_a_run_on_the_lossy_lane_leaves_its_latest_message() -> None:
    side = Side(True, {}, 1 << 20)
    lane = side.session.open_lossy_lane(0, lambda: None)
    chosen, topic_handlers._BATCH_SINK = topic_handlers._BATCH_SINK, True
    try:
        side.session.receive_lossy_frame(
            json.dumps({"op": "subscribe", "topic": "/t", "type": STRING}), side.clock.now
        )
    finally:
        topic_handlers._BATCH_SINK = chosen
    side.read(None)
    side.publish(["a", "b", "c"], 1, LIFESPAN)
    frame = side.session.lossy_frame_to_send()
    assert frame is not None and json.loads(frame.data)["msg"] == {"data": "c"}
    assert lane.replaced == 2
    side.read(None)
    assert side.frames == []  # nothing of it on the reliable channel
    side.session.close()


def test_a_run_that_cannot_be_encoded_is_told_as_each_message_would_be(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    received = []
    for batch in (True, False):
        side = Side(batch, {"compression": "cbor-raw"}, 1 << 20)
        codec = codec_for(side.graph.registry, side.graph.registry.message(STRING))

        def broken(msg: object) -> bytes:
            raise KeyError(STRING)

        monkeypatch.setattr(codec, "serialize", broken)
        side.read(None)
        msgs: list[dict[str, object] | None] = [{"data": "a"}, {"data": "b"}]
        side.graph.port.publish_local_many("pub", "/t", msgs, [None, None])
        side.read(None)
        received.append([json.loads(data) for _, data in side.frames])
        side.session.close()
    fast, general = received
    assert fast == general
    assert fast and all(
        (m["op"], m["level"], m["msg"])
        == ("status", "error", "subscribe: cannot send a message of /t as cbor-raw")
        for m in fast
    )


def test_a_closing_connection_queues_nothing_of_a_run() -> None:
    side = Side(True, {}, 1 << 20)
    side.read(None)
    side.session.request_close(CloseCode.GOING_AWAY, "bye")
    side.publish(["a", "b"], 1, LIFESPAN)
    side.read(None)
    assert side.frames == []


def test_an_oversized_message_in_a_run_is_held_alone_as_one_by_one() -> None:
    # over the send buffer: held while no other topic message waits, and the run's
    # messages after it are dropped until it is taken (D24), on both paths alike
    sides = [Side(batch, {}, 2500) for batch in (True, False)]
    for side in sides:
        side.read(None)
        side.publish(["big".ljust(3000, "x"), "after", "after too"], 1, LIFESPAN)
        side.publish(["later"], 1, 0.0)
        side.read(None)
        side.publish(["next", "big again".ljust(3000, "x")], 1, LIFESPAN)
        side.tick(50)
        side.read(None)
    fast, general = sides
    assert fast.frames == general.frames
    ops = [json.loads(data) for _, data in fast.frames]
    texts = [op["msg"]["data"][:9] for op in ops if op["op"] == "publish"]
    assert texts == ["bigxxxxxx", "next"]  # the second big one dropped: "next" waited
    warnings = [op["msg"] for op in ops if op["op"] == "status"]
    assert warnings[-1].startswith("dropped a 3047-byte message of /t")
    assert fast.session.stats.dropped_frames == general.session.stats.dropped_frames == 4
