"""The HTTP API under the envelope, and a topic's rate: the same bounds, told per request.

``POST /api/topics/cmd_vel`` with ``linear.x`` 3.0 (httpx, as a script would) reaches the
robot as 0.5 and the answer says so; a joint command out of bounds is a 400 naming the
field, its bound and the value, and nothing is delivered. Past ``max_rate_hz`` (all remote
clients of the topic together, a burst of ``RATE_BURST``) commands are dropped: a
rosbridge client gets one warning for the episode, an HTTP request a 429 each (D67).
"""

from __future__ import annotations

import anyio
import httpx
import pytest

from rwt import ServerConfig
from rwt_graph.safety.envelope import RATE_BURST
from tests.http.support import api_server
from tests.safety.example import EXAMPLE, Robot, twist
from tests.support.clients import is_op, running_server

pytestmark = pytest.mark.anyio

RATED = """\
[[topic]]
name = "/cmd_vel"
type = "geometry_msgs/msg/Twist"
max_rate_hz = 1
"""


async def test_an_http_publish_is_clamped_and_told() -> None:
    robot = Robot.make(EXAMPLE)
    async with (
        api_server(robot.graph, ServerConfig(tf=False)) as (_, url),
        httpx.AsyncClient(base_url=url, timeout=20) as http,
    ):
        answer = await http.post("/api/topics/cmd_vel", json={"linear": {"x": 3.0}})
        assert answer.status_code == 200, answer.text
        assert answer.json()["warnings"] == [
            "/cmd_vel: linear.x 3 clamped to 0.5 (bound [-0.5, 0.5])"
        ]
        refused = await http.post("/api/topics/arm/joint_cmd", json={"data": 9.0})
        assert refused.status_code == 400
        assert "data 9 is outside [0, 3.14]" in refused.json()["error"]
        fine = await http.post("/api/topics/arm/joint_cmd", json={"data": 1.0})
        assert fine.status_code == 200
        assert "warnings" not in fine.json()
        await robot.wait_for(lambda: robot.cmd_vel and robot.joint, "the commands")
    assert robot.twists[0]["linear"]["x"] == 0.5
    assert robot.joint == [1.0]


async def test_past_the_rate_commands_are_dropped() -> None:
    robot = Robot.make(RATED)
    async with running_server(ServerConfig(host="127.0.0.1"), graph=robot.graph) as harness:
        client = await harness.connect("ws")
        await client.send({"op": "set_level", "level": "warning"})
        for number in range(10):  # at once: past 1 a second and its burst
            op = {"op": "publish", "id": number, "topic": "/cmd_vel", "type": "geometry_msgs/Twist"}
            await client.send({**op, "msg": twist(0.1)})
        with anyio.fail_after(20):
            warning = await client.expect(is_op("status", level="warning"))
            await client.send({"op": "set_level", "level": "error"})  # a round trip: all read
            await client.send({"op": "call_service", "id": "sync", "service": "/rosapi/get_time"})
            await client.expect(is_op("service_response", id="sync"))
        assert "more than 1 commands a second: dropped" in warning["msg"]
        assert not [m for m in client.backlog if m.get("level") == "warning"]  # one an episode
        assert RATE_BURST <= len(robot.cmd_vel) < 10

        url = harness.server.urls["websocket"].replace("ws://", "http://")
        async with httpx.AsyncClient(base_url=url, timeout=20) as http:
            answers = [await http.post("/api/topics/cmd_vel", json=twist(0.1)) for _ in range(6)]
        dropped = [a for a in answers if a.status_code == 429]
        assert dropped  # each request is told
        assert "more than 1 commands a second: dropped" in dropped[0].json()["error"]
