"""Garbage from one raw WebSocket client does not hurt it, or anybody else."""

from __future__ import annotations

import json
import time
from itertools import count

import pytest
from websockets.sync.client import ClientConnection
from websockets.sync.client import connect as ws_connect

RECV_TIMEOUT = 5.0
_tokens = count(1)

GARBAGE = [
    ("not json", None),
    ("5", None),
    ('"op"', None),
    ('{"op":"nope"}', None),
    ('{"op":["x"]}', None),
    ('{"op":"subscribe"}', None),
    ('{"op":"nope","id":"bad-1"}', "bad-1"),
    ('{"op":"subscribe","id":"bad-2"}', "bad-2"),
]


def recv(ws: ClientConnection, what: str) -> dict:
    try:
        frame = ws.recv(timeout=RECV_TIMEOUT)
    except TimeoutError:
        pytest.fail(f"no frame within {RECV_TIMEOUT}s while waiting for {what}")
    assert isinstance(frame, str), f"expected a JSON text frame, got binary {frame[:60]!r}"
    return json.loads(frame)


def send(ws: ClientConnection, **op: object) -> None:
    ws.send(json.dumps(op))


def sync(ws: ClientConnection, name: str) -> list[dict]:
    """Barrier over a loopback topic; returns the frames that arrived before it."""
    topic = f"/rwt_test_sync/raw_{name}"
    token = f"{name}:{next(_tokens)}"
    send(ws, op="advertise", topic=topic, type="std_msgs/String")
    send(ws, op="subscribe", topic=topic, type="std_msgs/String")
    send(ws, op="publish", topic=topic, msg={"data": token})
    before = []
    deadline = time.monotonic() + RECV_TIMEOUT
    while time.monotonic() < deadline:
        frame = recv(ws, f"sync token {token}")
        if frame.get("op") == "publish" and frame.get("topic") == topic:
            if frame["msg"] == {"data": token}:
                return before
            continue
        before.append(frame)
    pytest.fail(f"sync token {token} did not come back in time; got {before}")


def test_garbage_gets_error_status_and_connection_survives(rwt_server):
    url = rwt_server.url
    with ws_connect(url) as bystander, ws_connect(url) as bad, ws_connect(url) as talker:
        send(bystander, op="subscribe", topic="/still_alive", type="std_msgs/String")
        assert sync(bystander, "bystander") == []

        for text, op_id in GARBAGE:
            bad.send(text)
            status = recv(bad, f"an error status for {text!r}")
            assert status.get("op") == "status", f"{text!r} -> {status}"
            assert status.get("level") == "error", f"{text!r} -> {status}"
            assert isinstance(status.get("msg"), str) and status["msg"], f"{text!r} -> {status}"
            assert "Traceback" not in status["msg"], f"{text!r} -> {status}"
            if op_id is not None:
                assert status.get("id") == op_id, f"{text!r} -> {status}"

        # The same connection still works.
        send(bad, op="subscribe", id="after-garbage", topic="/still_alive", type="std_msgs/String")
        assert sync(bad, "bad") == []

        send(talker, op="advertise", topic="/still_alive", type="std_msgs/String")
        send(talker, op="publish", topic="/still_alive", msg={"data": "still here"})
        assert sync(talker, "talker") == []

        expected = {"op": "publish", "topic": "/still_alive", "msg": {"data": "still here"}}
        for ws, who in ((bad, "the client that sent garbage"), (bystander, "the bystander")):
            frame = recv(ws, f"the publish at {who}")
            assert {k: frame.get(k) for k in expected} == expected, f"{who} got {frame}"
        # Nobody else saw any of the error statuses.
        assert sync(bystander, "bystander") == []
        assert sync(talker, "talker") == []


def test_wrong_field_type_is_rejected_and_not_published(rwt_server):
    """A publish whose msg does not fit the type: error status, nothing delivered."""
    url = rwt_server.url
    with ws_connect(url) as listener, ws_connect(url) as talker:
        send(listener, op="subscribe", topic="/typed", type="std_msgs/String")
        assert sync(listener, "listener") == []
        send(talker, op="advertise", topic="/typed", type="std_msgs/String")
        send(talker, op="publish", id="bad-msg", topic="/typed", msg={"data": 5})
        send(talker, op="publish", topic="/typed", msg={"data": "fine"})
        frames = sync(talker, "talker")
        assert [(f.get("op"), f.get("level"), f.get("id")) for f in frames] == [
            ("status", "error", "bad-msg")
        ], frames
        frame = recv(listener, "the good publish")
        assert frame.get("msg") == {"data": "fine"}, f"listener got {frame}"
        assert sync(listener, "listener") == []
