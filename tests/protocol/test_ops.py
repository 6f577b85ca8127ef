"""Every op of both spec editions parses; every malformed frame is a clear error."""

from __future__ import annotations

import contextlib
import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from rwt_protocol.codecs.json import decode_json, encode_op, parse_object
from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.ops import OP_MODELS, OpModel


def parse(frame: str | bytes) -> OpModel:
    return parse_object(decode_json(frame))


# One example of every op, with every optional field the spec or real clients use.
EXAMPLES: dict[str, dict[str, object]] = {
    "advertise": {
        "topic": "/chatter",
        "type": "std_msgs/String",
        "id": "a1",
        "latch": True,
        "queue_size": 10,
    },
    "unadvertise": {"topic": "/chatter", "id": "a1"},
    "publish": {"topic": "/chatter", "msg": {"data": "hi"}, "id": 3, "latch": False},
    "subscribe": {
        "topic": "/chatter",
        "type": "std_msgs/msg/String",
        "id": "s",
        "throttle_rate": 5,
        "queue_length": 2,
        "fragment_size": 100,
        "compression": "cbor",
    },
    "unsubscribe": {"topic": "/chatter", "id": "s"},
    "advertise_service": {"service": "/add", "type": "example_interfaces/AddTwoInts"},
    "unadvertise_service": {"service": "/add"},
    "call_service": {
        "service": "/add",
        "args": {"a": 1, "b": 2},
        "id": "c",
        "fragment_size": 9,
        "compression": "png",
        "type": "example_interfaces/AddTwoInts",
        "timeout": 2.5,
    },
    "service_response": {"service": "/add", "id": "c", "values": {"sum": 3}, "result": True},
    "advertise_action": {"action": "/fib", "type": "example_interfaces/Fibonacci"},
    "unadvertise_action": {"action": "/fib"},
    "send_action_goal": {
        "action": "/fib",
        "action_type": "example_interfaces/Fibonacci",
        "args": {"order": 5},
        "feedback": True,
        "id": "g",
        "fragment_size": 50,
        "compression": "none",
    },
    "cancel_action_goal": {"action": "/fib", "id": "g"},
    "action_feedback": {"action": "/fib", "id": "g", "values": {"sequence": [0, 1]}},
    "action_result": {
        "action": "/fib",
        "id": "g",
        "values": {"sequence": [0, 1, 1]},
        "status": 4,
        "result": True,
    },
    "fragment": {"id": "m", "data": '{"op"', "num": 0, "total": 3},
    "png": {"data": "iVBORw0KGgo=", "id": "p", "num": 0, "total": 1},
    "set_level": {"level": "warning", "id": "l"},
    "status": {"level": "error", "msg": "bad", "id": "x"},
    "auth": {
        "mac": "ab",
        "client": "1.2.3.4",
        "dest": "5.6.7.8",
        "rand": "r",
        "t": 1700000000.5,
        "level": "admin",
        "end": 1700000100,
    },
}


def test_every_op_has_an_example() -> None:
    assert set(EXAMPLES) == set(OP_MODELS)


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_op_parses_with_every_field_and_round_trips(name: str) -> None:
    frame = {"op": name, **EXAMPLES[name]}
    op = parse(json.dumps(frame))
    assert op.op == name
    again = json.loads(encode_op(op))
    for key, value in frame.items():
        assert again[key] == value


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_unknown_fields_are_ignored(name: str) -> None:
    op = parse(json.dumps({"op": name, **EXAMPLES[name], "x_extension": [1, 2]}))
    assert "x_extension" not in json.loads(encode_op(op))


@pytest.mark.parametrize("op_id", ["fred", 7, -1, ""])
def test_id_is_echoed_as_sent(op_id: object) -> None:
    op = parse(json.dumps({"op": "unsubscribe", "topic": "/a", "id": op_id}))
    assert op.id == op_id  # type: ignore[attr-defined]
    assert type(op.id) is type(op_id)  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("frame", "text"),
    [
        ("not json", "invalid JSON"),
        ("", "invalid JSON"),
        ("5", "expected a JSON object, got int"),
        ('"op"', "expected a JSON object, got str"),
        ('["op", "id"]', "expected a JSON object, got array"),
        ("null", "expected a JSON object, got null"),
        ("{}", "missing field at $.op"),
        ('{"op": ["x"]}', "expected str, got array at $.op"),
        ('{"op": {"a": 1}}', "expected str, got object at $.op"),
        ('{"op": "nope"}', "unknown op 'nope'"),
        ('{"op": "subscribe"}', "subscribe: missing field at $.topic"),
        ('{"op": "subscribe", "topic": 3}', "subscribe: expected str, got int at $.topic"),
        (
            '{"op": "subscribe", "topic": "/a", "throttle_rate": "fast"}',
            "subscribe: expected int, got str at $.throttle_rate",
        ),
        (
            '{"op": "subscribe", "topic": "/a", "throttle_rate": 1.5}',
            "subscribe: expected int, got float at $.throttle_rate",
        ),
        (
            '{"op": "subscribe", "topic": "/a", "queue_length": true}',
            "subscribe: expected int, got bool at $.queue_length",
        ),
        (
            '{"op": "subscribe", "topic": "/a", "fragment_size": 0}',
            "subscribe: expected a number >= 1, got 0 at $.fragment_size",
        ),
        ('{"op": "subscribe", "topic": "/a", "compression": 9000}', "subscribe: expected one of"),
        (
            '{"op": "advertise", "topic": "/a", "type": 3}',
            "advertise: expected str, got int at $.type",
        ),
        (
            '{"op": "publish", "topic": "/a", "id": true}',
            "publish: expected str or int, got bool at $.id",
        ),
        (
            '{"op": "service_response", "service": 5, "result": "error"}',
            "service_response: expected str, got int at $.service",
        ),
        ('{"op": "set_level", "level": "loud"}', "set_level: expected one of"),
        (
            '{"op": "call_service", "service": "/s", "timeout": -1}',
            "call_service: expected a number > 0",
        ),
        (
            '{"op": "fragment", "id": "m", "data": "x", "num": 0, "total": 2.5}',
            "fragment: expected int, got float at $.total",
        ),
    ],
)
def test_malformed_frames_are_remote_errors_with_a_path(frame: str, text: str) -> None:
    with pytest.raises(RemoteProtocolError) as info:
        parse(frame)
    assert text in info.value.message


def test_nan_literals_from_python_clients_are_accepted() -> None:
    op = parse('{"op": "publish", "topic": "/a", "msg": {"data": NaN}}')
    assert op.msg["data"] != op.msg["data"]  # type: ignore[attr-defined]


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=20,
)


@given(json_values)
def test_any_json_value_parses_or_fails_with_a_remote_error(value: object) -> None:
    with contextlib.suppress(RemoteProtocolError):
        parse(json.dumps(value))


@given(
    st.sampled_from(sorted(EXAMPLES)),
    st.dictionaries(st.text(max_size=12), json_values, max_size=6),
)
def test_any_fields_on_any_op_parse_or_fail_cleanly(name: str, fields: dict[str, object]) -> None:
    try:
        parse(json.dumps({**fields, "op": name}))
    except RemoteProtocolError as exc:
        assert exc.message.startswith(f"{name}: ")
