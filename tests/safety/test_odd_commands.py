"""Commands of every shape a bound can meet: integer fields, arrays, CBOR typed arrays.

An integer field is clamped to a whole number inside its bound (docs/safety.md, "The
rules file": ``on_violation``); a NaN or an infinity in a float array is refused like
one in a field (D67); a CBOR client's typed arrays (RFC 8746) are bounded, clamped on
a copy and told of, in the audit and the warning, as a JSON client's lists are; a topic
without rules is not touched; past ``max_rate_hz`` a command is dropped (D66, D69).
"""

from __future__ import annotations

import json
import logging
import struct
from collections import defaultdict
from collections.abc import AsyncIterator
from typing import Any

import anyio
import cbor2
import pytest
from websockets.asyncio.client import ClientConnection, connect

from rwt import Graph, ServerConfig
from rwt.safety import parse_rules
from tests.safety.example import HANG_S
from tests.support.clients import Client, Harness, is_op, running_server

pytestmark = pytest.mark.anyio

Message = dict[str, Any]

RULES = """\
[[topic]]
name = "/gear"
type = "std_msgs/msg/Int32"
on_violation = "clamp"
[topic.bounds]
"data" = [0.5, 3.5]

[[topic]]
name = "/level"
type = "std_msgs/msg/Int32"
[topic.bounds]
"data" = [0, 100]

[[topic]]
name = "/joints"
type = "sensor_msgs/msg/JointState"
on_violation = "clamp"
[topic.bounds]
"position[0]" = [0, 1]
"velocity[*]" = [-2, 2]

[[topic]]
name = "/slow"
type = "std_msgs/msg/Float64"
max_rate_hz = 0.001
"""
TOPICS = {
    "/gear": "std_msgs/msg/Int32",
    "/level": "std_msgs/msg/Int32",
    "/joints": "sensor_msgs/msg/JointState",
    "/slow": "std_msgs/msg/Float64",
    "/chatter": "std_msgs/msg/String",
}


class Heard:
    """What the robot's own subscribers of ``TOPICS`` hear, per topic."""

    def __init__(self, graph: Graph) -> None:
        self.graph = graph
        self.on: dict[str, list[Message]] = defaultdict(list)
        for topic, msgtype in TOPICS.items():
            graph.create_subscription(topic, self.on[topic].append, msgtype)

    async def wait(self, topic: str, count: int) -> list[Message]:
        """The first ``count`` messages of ``topic``, within the hang guard."""
        with anyio.fail_after(HANG_S):
            while len(self.on[topic]) < count:
                await anyio.sleep(0.01)
        return self.on[topic]


@pytest.fixture
async def served() -> AsyncIterator[tuple[Heard, Harness]]:
    heard = Heard(Graph(safety=parse_rules(RULES, "odd.toml")))
    async with running_server(ServerConfig(host="127.0.0.1"), graph=heard.graph) as harness:
        yield heard, harness


async def _status(client: Client, level: str, op_id: str) -> str:
    with anyio.fail_after(HANG_S):
        return str((await client.expect(is_op("status", level=level, id=op_id)))["msg"])


async def test_an_integer_field_is_clamped_to_a_whole_number_and_refused_as_one(
    served: tuple[Heard, Harness],
) -> None:
    heard, harness = served
    client = await harness.connect("ws")
    await client.send({"op": "set_level", "level": "warning"})
    for topic in ("/gear", "/level", "/chatter"):
        await client.send({"op": "advertise", "topic": topic, "type": TOPICS[topic]})
    await client.send({"op": "publish", "id": "high", "topic": "/gear", "msg": {"data": 7}})
    await client.send({"op": "publish", "id": "low", "topic": "/gear", "msg": {"data": -2}})
    assert [m["data"] for m in await heard.wait("/gear", 2)] == [3, 1]  # inside [0.5, 3.5]
    assert "data 7 clamped to 3 (bound [0.5, 3.5])" in await _status(client, "warning", "high")
    await client.send({"op": "publish", "id": "far", "topic": "/level", "msg": {"data": 500}})
    assert "/level: data 500 is outside [0, 100]" in await _status(client, "error", "far")
    # a topic without rules is not the envelope's
    await client.send({"op": "publish", "topic": "/chatter", "msg": {"data": "NaN 1e9"}})
    assert (await heard.wait("/chatter", 1))[0]["data"] == "NaN 1e9"
    assert heard.on["/level"] == []


async def test_a_non_finite_element_of_an_array_is_refused_and_shown_as_json_shows_it(
    served: tuple[Heard, Harness],
) -> None:
    heard, harness = served
    client = await harness.connect("tcp")
    await client.send({"op": "advertise", "topic": "/joints", "type": TOPICS["/joints"]})
    await client.send_raw(
        b'{"op": "publish", "id": "nan", "topic": "/joints",'
        b' "msg": {"position": [0.5], "velocity": [1.0, NaN]}}'
    )
    assert "/joints: velocity[1] is NaN, not a finite number" in await _status(
        client, "error", "nan"
    )
    await client.send_raw(
        b'{"op": "publish", "id": "inf", "topic": "/joints", "msg": {"position": [Infinity]}}'
    )
    assert "position[0] is Infinity, not a finite number" in await _status(client, "error", "inf")
    await client.send({"op": "publish", "topic": "/joints", "msg": {"velocity": [3.0, -9.0]}})
    assert list((await heard.wait("/joints", 1))[0]["velocity"]) == [2.0, -2.0]
    envelope = heard.graph.safety
    assert envelope is not None
    events = json.loads(json.dumps(envelope.status()["events"], allow_nan=False))  # JSON: no NaN
    assert [(e["kind"], e["field"], e["value"]) for e in events] == [
        ("reject", "velocity[1]", "NaN"),
        ("reject", "position[0]", "Infinity"),
        ("clamp", "velocity[0]", 3.0),  # one event per bound: "sent 2, and 1 more of velocity[*]"
    ]
    assert events[-1]["detail"] == "sent 2, and 1 more of velocity[*]"


async def _cbor_status(ws: ClientConnection, op_id: str) -> Message:
    with anyio.fail_after(HANG_S):
        while True:
            frame = await ws.recv()
            message = cbor2.loads(frame) if isinstance(frame, bytes) else json.loads(frame)
            if message.get("op") == "status" and message.get("id") == op_id:
                return message  # type: ignore[no-any-return]


async def test_cbor_typed_arrays_are_bounded_as_lists_are(
    served: tuple[Heard, Harness], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, "rwt.safety")
    heard, harness = served
    async with connect(harness.server.urls["websocket"], ping_interval=None) as ws:
        await ws.send(json.dumps({"op": "set_level", "level": "warning"}))
        await ws.send(
            cbor2.dumps({"op": "advertise", "topic": "/joints", "type": TOPICS["/joints"]})
        )
        arrays = {
            "position": cbor2.CBORTag(85, struct.pack("<2f", 5.0, 7.0)),  # float32
            "velocity": cbor2.CBORTag(86, struct.pack("<3d", 3.0, -1.0, -9.0)),  # float64
        }
        await ws.send(
            cbor2.dumps({"op": "publish", "id": "typed", "topic": "/joints", "msg": arrays})
        )
        warning = str((await _cbor_status(ws, "typed"))["msg"])
        nan = {"velocity": cbor2.CBORTag(86, struct.pack("<2d", 1.0, float("nan")))}
        await ws.send(cbor2.dumps({"op": "publish", "id": "nan", "topic": "/joints", "msg": nan}))
        error = str((await _cbor_status(ws, "nan"))["msg"])
    joints = (await heard.wait("/joints", 1))[0]
    assert (list(joints["position"]), list(joints["velocity"])) == ([1.0, 7.0], [2.0, -1.0, -2.0])
    assert warning.endswith(
        "/joints: position[0] 5 clamped to 1 (bound [0, 1]); "
        "velocity[0] 3 clamped to 2 (bound [-2, 2]), and 1 more of velocity[*]"
    )
    assert "/joints: velocity[1] is NaN, not a finite number" in error
    lines = [r.getMessage() for r in caplog.records if r.name == "rwt.safety"]
    clamp = next(line for line in lines if "field=position[0]" in line)
    assert " value=5.0 bound=[0,1] detail='sent 1'" in clamp  # a number, as a JSON client's
    assert len(heard.on["/joints"]) == 1


async def test_a_large_array_out_of_its_bound_is_one_event_and_one_clause(
    served: tuple[Heard, Harness], caplog: pytest.LogCaptureFixture
) -> None:
    """Whatever the count a client sends out of a bound, the log and its warning stay one."""
    caplog.set_level(logging.INFO, "rwt.safety")
    heard, harness = served
    client = await harness.connect("ws")
    await client.send({"op": "set_level", "level": "warning"})
    await client.send({"op": "advertise", "topic": "/joints", "type": TOPICS["/joints"]})
    many = {"position": [0.5], "velocity": [9.0] * 5000}
    for op_id in ("many", "again"):
        await client.send({"op": "publish", "id": op_id, "topic": "/joints", "msg": many})
    warning = await _status(client, "warning", "many")
    joints = await heard.wait("/joints", 2)
    assert [list(msg["velocity"]) for msg in joints] == [[2.0] * 5000] * 2
    assert warning == (
        "publish: /joints: velocity[0] 9 clamped to 2 (bound [-2, 2]), and 4999 more of velocity[*]"
    )
    lines = [r.getMessage() for r in caplog.records if r.name == "rwt.safety"]
    assert len(lines) == 1 and "field=velocity[0] value=9.0" in lines[0]
    assert many["velocity"] == [9.0] * 5000  # the client's message is not changed


async def test_past_its_rate_a_command_is_dropped_for_every_remote_client() -> None:
    heard = Heard(Graph(safety=parse_rules(RULES, "odd.toml")))
    for number in range(4):  # the graph's own port: no notes to tell
        heard.graph.port.publish(f"ws:10.0.0.{number}:4000#1", "/slow", {"data": float(number)})
    assert [m["data"] for m in heard.on["/slow"]] == [0.0, 1.0]  # a burst of RATE_BURST
    envelope = heard.graph.safety
    assert envelope is not None
    drops = [e for e in envelope.audit.last() if e.kind == "rate_drop"]
    assert [e.client for e in drops] == ["ws:10.0.0.2:4000#1", "ws:10.0.0.3:4000#1"]
    assert drops[0].detail == "/slow: more than 0.001 commands a second: dropped"
