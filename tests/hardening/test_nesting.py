"""Deeply nested frames: one status ``nesting deeper than 100``, no traceback, still served.

``codec.MAX_NESTING`` (docs/limits.md) bounds the nesting of arrays and objects
in any incoming frame, JSON or CBOR, the op object being level 1. The check
uses no recursion, and a decoder's own ``RecursionError`` (msgspec, json) on
100 000 levels means the same refusal, not a bug.
"""

from __future__ import annotations

import logging

import anyio
import cbor2
import pytest

from rwt_graph.graph import Graph
from rwt_protocol.codecs.json import MAX_NESTING
from tests.conftest import Peer
from tests.hardening.test_unencodable import send_binary
from tests.session.test_robustness import pair, still_served
from tests.support.clients import TRANSPORTS, Harness, is_op

TOO_DEEP = f"nesting deeper than {MAX_NESTING}"


def nested_json(levels: int, inner: bytes = b"1") -> bytes:
    """``levels`` arrays around ``inner`` (an array is one level)."""
    return b"[" * levels + inner + b"]" * levels


def publish_nested(levels: int) -> bytes:
    """A publish op whose ``msg`` makes the frame ``levels`` deep in all (the op is 1)."""
    inner = b'{"a":' * (levels - 2) + b"1" + b"}" * (levels - 2)
    return b'{"op":"publish","topic":"/probe","msg":{"data":' + inner + b"}}"


def nested_cbor(levels: int) -> bytes:
    return b"\x81" * levels + b"\x01"


def deep_list(levels: int) -> object:
    value: object = 1
    for _ in range(levels):
        value = [value]
    return value


def statuses_only(peer: Peer) -> list[str]:
    frames = peer.received()
    assert all(f["op"] == "status" and f["level"] == "error" for f in frames), frames
    return [str(f["msg"]) for f in frames]


@pytest.mark.parametrize(
    "frame",
    [
        b"[" * 100_000,
        nested_json(100_000),
        b'{"op":"publish","topic":"/probe","msg":' + nested_json(100_000, b"NaN") + b"}",
        nested_json(MAX_NESTING + 1),
        b'{"op":"publish","topic":"/probe","msg":' + nested_json(MAX_NESTING) + b"}",
        publish_nested(MAX_NESTING + 1),
        nested_json(MAX_NESTING + 1, b"NaN"),  # the json fallback path
    ],
    ids=[
        "100k-open",
        "100k-closed",
        "100k-nan",
        "limit+1",
        "publish-array-limit+1",
        "publish-object-limit+1",
        "nan-limit+1",
    ],
)
def test_deep_json_gets_one_status_and_no_traceback(
    graph: Graph, frame: bytes, caplog: pytest.LogCaptureFixture
) -> None:
    sender, other = pair(graph)
    with caplog.at_level(logging.DEBUG):
        sender.send_raw(frame)
        sender.send_raw(frame.decode())  # a text frame takes the same path
    assert statuses_only(sender) == [TOO_DEEP, TOO_DEEP]
    assert not [r for r in caplog.records if r.exc_info or r.levelno >= logging.WARNING]
    still_served(sender, other)


@pytest.mark.parametrize(
    "frame",
    [
        nested_cbor(100_000),
        nested_cbor(MAX_NESTING + 1),
        # the op is level 1, msg 2: MAX_NESTING - 1 lists inside reach MAX_NESTING + 1
        cbor2.dumps({"op": "publish", "topic": "/a", "msg": {"d": deep_list(MAX_NESTING - 1)}}),
        # a large frame (its first map levels decoded apart) with a deep value in its msg
        cbor2.dumps(
            {
                "op": "publish",
                "topic": "/probe",
                "msg": {"blob": b"x" * 70_000, "deep": deep_list(MAX_NESTING - 1)},
            }
        ),
    ],
    ids=["100k", "limit+1", "in-msg", "large-frame"],
)
def test_deep_cbor_gets_one_status_and_no_traceback(
    graph: Graph, frame: bytes, caplog: pytest.LogCaptureFixture
) -> None:
    sender, other = pair(graph)
    with caplog.at_level(logging.DEBUG):
        sender.session.receive_frame(frame, sender.clock.monotonic(), binary=True)
    assert statuses_only(sender) == [TOO_DEEP]
    assert not [r for r in caplog.records if r.exc_info or r.levelno >= logging.WARNING]
    still_served(sender, other)


def test_nesting_up_to_the_limit_is_not_refused_for_depth(graph: Graph) -> None:
    sender, other = pair(graph)
    sender.send_raw(nested_json(MAX_NESTING))
    sender.send_raw(publish_nested(MAX_NESTING))
    sender.session.receive_frame(nested_cbor(MAX_NESTING), 0.0, binary=True)
    texts = statuses_only(sender)
    assert len(texts) == 3 and not any("nesting" in text for text in texts)  # other errors
    still_served(sender, other)


def test_a_wide_frame_of_many_small_objects_is_served(graph: Graph) -> None:
    """Many containers side by side are not deep: the walk is linear, not refused."""
    sender, other = pair(graph)
    sender.send(op="advertise", topic="/poses", type="geometry_msgs/PoseArray")
    other.send(op="subscribe", topic="/poses")
    pose = {"position": {"x": 1.0, "y": 2.0, "z": 3.0}, "orientation": {"w": 1.0}}
    sender.send(op="publish", topic="/poses", msg={"poses": [pose] * 20_000})
    [message] = other.received()
    assert len(message["msg"]["poses"]) == 20_000
    assert sender.statuses() == []


# ---- over the real transports ------------------------------------------------

TIMEOUT_S = 10
LEVELS = 30_000  # deeper than any recursion limit; 60 KB fits one UDP datagram


@pytest.mark.anyio
@pytest.mark.parametrize("transport", TRANSPORTS)
async def test_deep_frames_over_every_transport(harness: Harness, transport: str) -> None:
    client = await harness.connect(transport)
    healthy = await harness.connect("ws", "healthy")
    with anyio.fail_after(TIMEOUT_S):
        await client.send_raw(nested_json(LEVELS) + client.terminator)
        status = await client.expect(is_op("status"))
        assert status == {"op": "status", "level": "error", "msg": TOO_DEEP}
        if transport != "stdio":  # stdio carries JSON lines only
            await send_binary(client, nested_cbor(LEVELS))
            status = await client.expect(is_op("status"))
            assert status == {"op": "status", "level": "error", "msg": TOO_DEEP}
        await client.send({"op": "set_level", "level": "info", "id": "alive"})
        assert (await client.expect(is_op("status", id="alive")))["level"] == "info"
        await healthy.send({"op": "set_level", "level": "info", "id": "fine"})
        assert (await healthy.expect(is_op("status", id="fine")))["level"] == "info"
