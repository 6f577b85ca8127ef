"""Outgoing encoding is total: an op with no wire form is replaced, never raised.

docs/limits.md: a reply becomes its failure reply, anything else an error status.
"""

from __future__ import annotations

import json
from typing import Any

import cbor2
import pytest

from rwt_graph.graph import Graph
from rwt_protocol import ops
from rwt_protocol.codecs.json import parse_object
from rwt_protocol.levels import StatusLevel
from rwt_protocol.ops.base import Compression
from rwt_protocol.server import handlers
from rwt_protocol.server.encoding import safe_op_frames
from tests.session.test_robustness import pair, still_served

LONE = "\ud800"


def built(message: dict[str, Any]) -> ops.OpModel:
    """The op ``message`` describes, built as rwt builds what it sends (not validated)."""
    fields = {key: value for key, value in message.items() if key != "op"}
    return ops.OP_MODELS[message["op"]](**fields)


def replaced(message: dict[str, Any], **kw: Any) -> dict[str, Any]:
    frames, failure = safe_op_frames(built(message), **kw)
    assert failure is not None and failure.op == message["op"]
    [frame] = frames
    assert not frame.binary
    return json.loads(frame.data)  # type: ignore[no-any-return]


@pytest.mark.parametrize("compression", ["none", "png", "cbor"])
def test_an_unencodable_service_response_becomes_its_failure_reply(compression: str) -> None:
    message = {"op": "service_response", "service": "/s", "values": {"m": LONE}, "result": True}
    reply = replaced({**message, "id": "c"}, compression=compression)
    assert reply["op"] == "service_response" and reply["result"] is False
    assert reply["service"] == "/s" and reply["id"] == "c"
    assert reply["values"].startswith("cannot encode the service_response: ")


def test_an_unencodable_action_result_aborts_the_goal() -> None:
    message = {"op": "action_result", "action": "/a", "id": 7, "values": {"n": 10**5000}}
    reply = replaced({**message, "status": 4, "result": True})
    assert reply == {
        "op": "action_result",
        "action": "/a",
        "values": reply["values"],
        "status": 6,
        "result": False,
        "id": 7,
    }
    assert "cannot encode the action_result" in reply["values"]


def test_an_unencodable_status_is_sent_with_its_text_escaped() -> None:
    status = replaced({"op": "status", "level": "warning", "msg": f"bad {LONE}", "id": LONE})
    assert status == {"op": "status", "level": "warning", "msg": "bad \\ud800", "id": "\\ud800"}


def test_any_other_unencodable_op_becomes_an_error_status_without_a_bad_id() -> None:
    status = replaced({"op": "call_service", "service": "/s", "args": {"a": LONE}, "id": 2**70})
    assert status["op"] == "status" and status["level"] == "error" and "id" not in status
    assert status["msg"].startswith("call_service: cannot encode the call_service: ")


@pytest.mark.parametrize(
    "message",
    [
        {"op": "service_response", "service": "/s", "values": {"m": LONE}, "result": True},
        {"op": "action_result", "action": "/a", "id": "g", "values": [LONE], "result": True},
        {"op": "status", "level": "loud", "msg": LONE},
        {"op": "publish", "topic": "/t", "msg": {"n": 10**5000}},
    ],
    ids=["service_response", "action_result", "status", "other"],
)
def test_every_replacement_is_a_valid_op_of_its_model(message: dict[str, Any]) -> None:
    op = parse_object(replaced(message))
    assert op.op in (message["op"], "status")


def test_an_encodable_op_is_untouched() -> None:
    message = {"op": "service_response", "service": "/s", "values": {}, "result": True}
    frames, failure = safe_op_frames(built(message), compression=Compression.CBOR)
    assert failure is None and cbor2.loads(frames[0].data) == message


def test_a_handler_reporting_unencodable_text_neither_raises_nor_looks_like_a_bug(
    graph: Graph, monkeypatch: pytest.MonkeyPatch
) -> None:
    def reports(session: Any, op: object, now: float) -> None:
        session.report(StatusLevel.ERROR, f"set_level: {LONE}", LONE)

    monkeypatch.setitem(handlers.HANDLERS, ops.SetLevel, reports)
    sender, other = pair(graph)
    sender.send(op="set_level", level="info", id="x")
    assert sender.statuses() == [
        {"op": "status", "level": "error", "msg": "set_level: \\ud800", "id": "\\ud800"}
    ]
    still_served(sender, other)
