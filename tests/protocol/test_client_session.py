"""The client role, sans-IO: ops out, events in (fragments, png, CBOR decoded)."""

from __future__ import annotations

import base64
import io
import json
import math
import struct

import cbor2
import pytest
from PIL import Image

from rwt_protocol.client import ClientEvent, ClientSession, UnknownOp
from rwt_protocol.levels import StatusLevel
from rwt_protocol.ops import (
    ActionFeedback,
    ActionResult,
    CallService,
    CancelActionGoal,
    Publish,
    PublishFrame,
    SendActionGoal,
    ServiceResponse,
    Status,
)

PUBLISH = '{"op":"publish","topic":"/t","msg":{"data":"hello"}}'


def published(events: list[ClientEvent]) -> list[tuple[str, object]]:
    """The topic messages among ``events``, as (topic, msg), whichever decoder made them."""
    return [(e.topic, e.msg) for e in events if getattr(e, "op", None) == "publish"]  # type: ignore[union-attr]


def sent(session: ClientSession) -> list[dict[str, object]]:
    return [json.loads(frame) for frame in session.frames_to_send()]


def test_ops_out_carry_ids_and_options() -> None:
    session = ClientSession()
    sub = session.subscribe("/t", "std_msgs/String", throttle_rate=100, fragment_size=None)
    call = session.call_service("/s", {"a": 1}, timeout=2.0)
    goal = session.send_action_goal(
        "/f", "example_interfaces/Fibonacci", {"order": 2}, feedback=True
    )
    assert sent(session) == [
        {
            "op": "subscribe",
            "id": sub,
            "topic": "/t",
            "type": "std_msgs/String",
            "throttle_rate": 100,
        },
        {"op": "call_service", "id": call, "service": "/s", "args": {"a": 1}, "timeout": 2.0},
        {
            "op": "send_action_goal",
            "id": goal,
            "action": "/f",
            "action_type": "example_interfaces/Fibonacci",
            "args": {"order": 2},
            "feedback": True,
        },
    ]
    assert len({sub, call, goal}) == 3


def test_replay_sends_standing_ops_again() -> None:
    session = ClientSession()
    session.set_level(StatusLevel.INFO)
    adv = session.advertise("/a", "std_msgs/String", latch=True)
    session.subscribe("/b")
    session.advertise_service("/s", "std_srvs/Trigger")
    session.advertise_action("/f", "example_interfaces/Fibonacci")
    session.unadvertise("/a", adv)
    first = sent(session)
    session.replay()
    replayed = sent(session)
    assert [op["op"] for op in replayed] == [
        "set_level",
        "subscribe",
        "advertise_service",
        "advertise_action",
    ]
    assert replayed[1:] == [first[2], first[3], first[4]]


def test_set_level_sends_the_wire_spelling() -> None:
    session = ClientSession()
    session.set_level(StatusLevel.WARNING)
    assert sent(session) == [{"op": "set_level", "level": "warning"}]


@pytest.mark.parametrize(
    ("frame", "event"),
    [
        (
            '{"op":"service_response","service":"/s","id":"c:1","values":{"x":1},"result":true}',
            ServiceResponse(id="c:1", service="/s", result=True, values={"x": 1}),
        ),
        (
            '{"op":"call_service","service":"/s","id":"r:1","args":{}}',
            CallService(id="r:1", service="/s", args={}),
        ),
        (
            '{"op":"send_action_goal","action":"/f","id":"g","action_type":"T","args":{"order":1}}',
            SendActionGoal(id="g", action="/f", action_type="T", args={"order": 1}),
        ),
        (
            '{"op":"cancel_action_goal","action":"/f","id":"g"}',
            CancelActionGoal(id="g", action="/f"),
        ),
        (
            '{"op":"action_feedback","action":"/f","id":"g","values":[1]}',
            ActionFeedback(id="g", action="/f", values=[1]),
        ),
        (
            '{"op":"action_result","action":"/f","id":"g","values":{},"result":true}',
            ActionResult(id="g", action="/f", result=True, status=4, values={}),
        ),
        (
            '{"op":"action_result","action":"/f","id":"g","result":false}',
            ActionResult(id="g", action="/f", result=False, status=6),
        ),
        ('{"op":"status","level":"error","msg":"x","id":3}', Status(level="error", msg="x", id=3)),
    ],
)
def test_incoming_ops_become_their_op_models(frame: str, event: object) -> None:
    assert ClientSession().receive_frame(frame) == [event]


def test_a_publish_is_its_model_or_its_twin_from_either_decoder() -> None:
    fast = ClientSession().receive_frame(PUBLISH)
    general = ClientSession().receive_frame(cbor2.dumps(json.loads(PUBLISH)))
    for [event] in (fast, general):
        assert isinstance(event, (Publish, PublishFrame))
        assert (event.op, event.topic, event.msg, event.id) == (
            "publish",
            "/t",
            {"data": "hello"},
            None,
        )


@pytest.mark.parametrize("frame", ["nope", "5", '{"op":"weird"}', '{"op":"publish"}', b"\xff\x00"])
def test_unusable_frames_are_reported_not_raised(frame: str | bytes) -> None:
    [event] = ClientSession().receive_frame(frame)
    assert isinstance(event, UnknownOp)


def test_fragments_are_reassembled_by_num_with_a_float_total() -> None:
    session = ClientSession()
    parts = [PUBLISH[i : i + 10] for i in range(0, len(PUBLISH), 10)]
    frames = [
        json.dumps(
            {"op": "fragment", "id": 0, "data": part, "num": num, "total": len(parts) - 0.0000001}
        )
        for num, part in enumerate(parts)
    ]
    events = []
    for frame in reversed(frames):
        events += session.receive_frame(frame)
    assert published(events) == [("/t", {"data": "hello"})]


def test_pending_fragments_are_bounded_and_forgotten() -> None:
    session = ClientSession(max_pending_fragment_bytes=400, fragment_timeout_s=10)

    def part(n: int, num: int, now: float) -> list[ClientEvent]:
        frame = {"op": "fragment", "id": n, "data": PUBLISH[num * 27 : num * 27 + 27]}
        return list(session.receive_frame(json.dumps({**frame, "num": num, "total": 2}), now))

    refused = [events for n in range(20) if (events := part(n, 0, now=1.0))]
    # about four incomplete messages fit in 400 bytes; the rest are reported, not held
    assert 10 <= len(refused) <= 17
    assert all(isinstance(e, UnknownOp) and "dropped" in e.reason for [e] in refused)
    # once the held ones are forgotten (10 s after their last part) there is room again
    assert part(99, 0, now=20.0) == []
    assert published(part(99, 1, now=20.0)) == [("/t", {"data": "hello"})]


def _png(text: str) -> str:
    data = text.encode()
    width = int(math.sqrt(len(data) / 3))
    height = math.ceil(len(data) / 3 / width)
    data += b"\n" * (width * height * 3 - len(data))
    buffer = io.BytesIO()
    Image.frombytes("RGB", (width, height), data).save(buffer, "PNG")
    return base64.b64encode(buffer.getvalue()).decode()


def test_png_is_decoded_whole_or_in_parts() -> None:
    session = ClientSession()
    data = _png(PUBLISH)
    whole = session.receive_frame(json.dumps({"op": "png", "data": data}))
    assert published(whole) == [("/t", {"data": "hello"})]
    half = len(data) // 2
    first = {"op": "png", "id": "p", "data": data[:half], "num": 0, "total": 2}
    second = {"op": "png", "id": "p", "data": data[half:], "num": 1, "total": 2}
    assert session.receive_frame(json.dumps(second)) == []
    assert published(session.receive_frame(json.dumps(first))) == [("/t", {"data": "hello"})]
    [bad] = session.receive_frame(json.dumps({"op": "png", "data": "bm90IGEgcG5n"}))
    assert isinstance(bad, UnknownOp)


def test_cbor_frames_with_typed_arrays() -> None:
    frame = cbor2.dumps(
        {
            "op": "publish",
            "topic": "/c",
            "msg": {
                "f": cbor2.CBORTag(86, struct.pack("<2d", 1.5, -2.0)),
                "i": cbor2.CBORTag(77, struct.pack("<3h", -1, 0, 7)),
                "u": cbor2.CBORTag(70, struct.pack("<I", 4000000000)),
                "raw": b"\x01\x02",
            },
        }
    )
    events = ClientSession().receive_frame(frame)
    assert published(events) == [
        ("/c", {"f": [1.5, -2.0], "i": [-1, 0, 7], "u": [4000000000], "raw": b"\x01\x02"})
    ]


def test_replies_are_validated_by_the_op_models() -> None:
    """A reply the server got wrong is reported, never read loosely (``"false"`` is not true)."""
    session = ClientSession()
    [event] = session.receive_frame(
        '{"op":"service_response","service":"/s","id":"c:1","result":"false","values":{}}'
    )
    assert isinstance(event, UnknownOp)
    assert "expected bool, got str at $.result" in event.reason
    [event] = session.receive_frame('{"op":"action_result","action":"/a","id":"g","result":true}')
    assert event == ActionResult(id="g", action="/a", result=True, status=4)  # omitted (D18)
