"""The send buffer limit bounds memory, not only payload (D24, benchmarks B8).

Each queued frame is charged its payload plus ``FRAME_OVERHEAD_BYTES``, so a
peer that reads nothing holds about the limit whatever the frame size; drops
are still counted and reported once per episode.
"""

from __future__ import annotations

import json

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.outbox import FRAME_OVERHEAD_BYTES, Outbox, OutFrame
from rwt_protocol.server.session import Session, SessionConfig

PAYLOAD = 100


def test_each_queued_frame_is_charged_its_payload_and_the_overhead() -> None:
    box = Outbox(limit_bytes=10 * (PAYLOAD + FRAME_OVERHEAD_BYTES))
    for i in range(25):
        box.push(OutFrame(b"%03d" % i + b"x" * (PAYLOAD - 3), droppable=True))
    assert box.queued_bytes == 10 * (PAYLOAD + FRAME_OVERHEAD_BYTES)
    assert box.dropped == 15
    kept = box.take(max_bytes=3 * PAYLOAD)  # batches are measured in payload bytes
    assert [f.data[:3] for f in kept] == [b"015", b"016", b"017"]
    assert box.queued_bytes == 7 * (PAYLOAD + FRAME_OVERHEAD_BYTES)
    assert len(box.drain()) == 7 and box.queued_bytes == 0


def test_undroppable_frames_are_charged_the_overhead_too() -> None:
    box = Outbox(limit_bytes=1 << 20)
    box.push(OutFrame(b"s" * PAYLOAD))
    box.push(OutFrame(b"t" * PAYLOAD, droppable=True))
    assert box.undroppable_bytes == PAYLOAD + FRAME_OVERHEAD_BYTES
    box.take(max_bytes=1)
    assert box.undroppable_bytes == 0 and box.queued_bytes == PAYLOAD + FRAME_OVERHEAD_BYTES


def test_a_stalled_subscriber_of_small_messages_keeps_fewer_than_payload_alone_allows(
    graph: Graph,
) -> None:
    limit = 64 * 1024
    session = Session(
        graph.port,
        "slow",
        config=SessionConfig(send_buffer_limit=limit, status_level=StatusLevel.WARNING),
    )
    session.receive_frame(
        json.dumps({"op": "subscribe", "topic": "/small", "type": "std_msgs/String"}), 0.0
    )
    publisher = graph.create_publisher("/small", "std_msgs/msg/String")
    sent = 2000
    for i in range(sent):
        publisher.publish({"data": f"{i:06d}"})
    frames = session.frames_to_send()
    messages = [json.loads(f.data) for f in frames]
    publishes = [m for m in messages if m["op"] == "publish"]
    [warning] = [m for m in messages if m["op"] == "status"]
    assert warning["level"] == "warning" and "dropping" in warning["msg"]
    size = len(frames[-1].data)
    assert len(publishes) <= limit // (size + FRAME_OVERHEAD_BYTES) + 1
    assert len(publishes) < limit // size // 2  # payload alone would keep over twice as many
    assert session.stats.dropped_frames == sent - len(publishes)
    assert [int(m["msg"]["data"]) for m in publishes] == list(range(sent - len(publishes), sent))
