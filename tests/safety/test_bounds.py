"""The envelope's bounds over rosbridge: every transport, every encoding, no way around it.

The example's rules on a served graph (docs/safety.md): a client of any transport
(WebSocket, TCP, UDP, stdio, an in-process connection, a WebRTC data channel)
publishes ``linear.x`` 2.0 and ``angular.z`` -5.0 on ``/cmd_vel`` and the robot's
subscriber gets 0.5 and -1.0, the client one warning for the episode; ``/arm/joint_cmd``
9.0 gets an error status naming ``data``, its bound and the value, and nothing is
delivered, then 1.0 arrives. CBOR ops and fragments take the same path; a second
advertise with another type, a type alias, a publish that would create the topic and
non-finite values (JSON's ``NaN`` and ``Infinity``) get nothing past it (D66, D67).
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from typing import Any

import anyio
import cbor2
import pytest
from websockets.asyncio.client import connect

from rwt import ServerConfig
from tests.safety.example import HANG_S, Robot, twist
from tests.support.clients import (
    CONTRACT_TRANSPORTS,
    Client,
    Harness,
    is_op,
    running_server,
)

pytestmark = pytest.mark.anyio

Message = dict[str, Any]


@pytest.fixture
async def served() -> AsyncIterator[tuple[Robot, Harness]]:
    """The example's robot, served on every transport (WebRTC where aiortc runs)."""
    robot = Robot.make()
    async with running_server(ServerConfig(host="127.0.0.1"), graph=robot.graph) as harness:
        yield robot, harness


async def _status(client: Client, level: str) -> Message:
    with anyio.fail_after(HANG_S):
        return await client.expect(is_op("status", level=level))


@pytest.mark.parametrize("transport", CONTRACT_TRANSPORTS)
async def test_every_transport_is_held_to_the_bounds(
    served: tuple[Robot, Harness], transport: str
) -> None:
    robot, harness = served
    client = await harness.connect(transport)
    await client.send({"op": "set_level", "level": "warning"})
    await client.send({"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist"})
    drive = {"op": "publish", "id": "drive", "topic": "/cmd_vel", "msg": twist(2.0, -5.0)}
    for _ in range(2):  # one episode: one warning
        await client.send(drive)
    await robot.wait_for(lambda: len(robot.cmd_vel) >= 2, "two twists")
    assert [(m["linear"]["x"], m["angular"]["z"]) for m in robot.twists] == [(0.5, -1.0)] * 2
    warning = await _status(client, "warning")
    assert warning["id"] == "drive"
    assert "linear.x 2 clamped to 0.5 (bound [-0.5, 0.5])" in warning["msg"]
    assert "angular.z -5 clamped to -1 (bound [-1, 1])" in warning["msg"]

    joint = {"topic": "/arm/joint_cmd", "type": "std_msgs/msg/Float64"}
    await client.send({"op": "advertise", **joint})
    await client.send({"op": "publish", "id": "far", "topic": joint["topic"], "msg": {"data": 9.0}})
    error = await _status(client, "error")
    assert error["id"] == "far"
    assert "data 9 is outside [0, 3.14]" in error["msg"]
    await client.send({"op": "publish", "topic": "/arm/joint_cmd", "msg": {"data": 1.0}})
    await robot.wait_for(lambda: robot.joint, "the joint command")
    assert robot.joint == [1.0]
    assert not [m for m in client.backlog if m.get("op") == "status" and m["level"] == "warning"]


async def test_cbor_ops_and_fragments_are_held_to_the_bounds(
    served: tuple[Robot, Harness],
) -> None:
    robot, harness = served
    url = harness.server.urls["websocket"]
    async with connect(url, ping_interval=None) as ws:
        await ws.send(json.dumps({"op": "set_level", "level": "warning"}))
        advertise = {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"}
        await ws.send(cbor2.dumps(advertise))
        await ws.send(cbor2.dumps({"op": "publish", "topic": "/cmd_vel", "msg": twist(3.0, 4.0)}))
        await robot.wait_for(lambda: robot.cmd_vel, "the CBOR twist")
        text = json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": twist(-7.0, 0.5)})
        parts = [text[i : i + 16] for i in range(0, len(text), 16)]
        for num in reversed(range(len(parts))):  # any order (spec 3.1.1)
            fragment = {"op": "fragment", "id": "big", "num": num, "total": len(parts)}
            await ws.send(json.dumps({**fragment, "data": parts[num]}))
        await robot.wait_for(lambda: len(robot.cmd_vel) >= 2, "the fragmented twist")
    assert [(m["linear"]["x"], m["angular"]["z"]) for m in robot.twists] == [
        (0.5, 1.0),
        (-0.5, 0.5),
    ]


async def test_no_way_around_the_envelope(served: tuple[Robot, Harness]) -> None:
    """Another type, a type alias, a publish that creates the topic, NaN and Infinity."""
    robot, harness = served
    client = await harness.connect("ws")
    second = {"op": "advertise", "id": "other", "topic": "/cmd_vel", "type": "std_msgs/msg/Float64"}
    await client.send(second)
    refused = await _status(client, "error")
    assert refused["id"] == "other"
    assert "established with type geometry_msgs/msg/Twist" in refused["msg"]
    # publish with a type advertises first (D48); ``cmd_vel`` and the ROS 1 spelling are the topic
    creating = {"op": "publish", "topic": "cmd_vel", "type": "geometry_msgs/Twist"}
    await client.send({**creating, "msg": twist(9.0)})
    typed = {"op": "publish", "topic": "//cmd_vel/", "type": "std_msgs/msg/String"}
    await client.send({**typed, "id": "string", "msg": {"data": "go"}})
    refused = await _status(client, "error")
    assert refused["id"] == "string"
    await client.send_raw(
        b'{"op": "publish", "id": "nan", "topic": "/cmd_vel",'
        b' "msg": {"linear": {"x": NaN}, "angular": {"z": 0.1}}}'
    )
    nan = await _status(client, "error")
    assert nan["id"] == "nan"
    assert "linear.x is NaN, not a finite number" in nan["msg"]
    await client.send_raw(
        b'{"op": "publish", "id": "inf", "topic": "/cmd_vel", "msg": {"linear": {"y": -Infinity}}}'
    )
    infinite = await _status(client, "error")
    assert "linear.y is -Infinity, not a finite number" in infinite["msg"]
    await client.send({"op": "publish", "topic": "/cmd_vel", "msg": twist(0.25)})
    await robot.wait_for(lambda: len(robot.cmd_vel) >= 2, "the twists")
    assert [m["linear"]["x"] for m in robot.twists] == [0.5, 0.25]


async def test_the_robots_own_side_is_not_bound(served: tuple[Robot, Harness]) -> None:
    robot, _ = served
    robot.graph.create_publisher("/cmd_vel", "geometry_msgs/msg/Twist").publish(twist(2.0))
    assert robot.twists == [twist(2.0)]
