"""The audit trail: a structured log line per event, the status topic, ``/version``.

Every clamp, rejection, rate drop, dead-man stop and approval is a line on the
``rwt.safety`` logger with the client, its front end, the topic, the field, the value
and the bound; what a client repeats is one line per episode, its repeats counted on
the first event, as the access log counts its refusals (docs/safety.md, D69). The
rules and the newest events are on the latched ``/rwt/safety`` topic (the console
shows them), and ``GET /version`` says an envelope is there.
"""

from __future__ import annotations

import json
import logging

import anyio
import httpx
import pytest

from rwt import ServerConfig
from rwt_graph.safety.envelope import STATUS_TOPIC
from tests.safety.example import STOP, Robot, twist
from tests.support.clients import is_op, running_server

pytestmark = pytest.mark.anyio


async def test_each_event_is_one_line_and_the_status_topic_shows_them(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, "rwt.safety")
    robot = Robot.make()
    async with running_server(ServerConfig(host="127.0.0.1"), graph=robot.graph) as harness:
        watcher = await harness.connect("ws", "watcher")
        await watcher.send({"op": "subscribe", "topic": STATUS_TOPIC, "type": "std_msgs/String"})
        driver = await harness.connect("tcp", "driver")
        for _ in range(3):  # one episode
            op = {"op": "publish", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist"}
            await driver.send({**op, "msg": twist(2.0)})
        joint = {"op": "publish", "topic": "/arm/joint_cmd", "type": "std_msgs/msg/Float64"}
        await driver.send({**joint, "msg": {"data": -1.0}})
        await robot.wait_for(lambda: len(robot.cmd_vel) == 3, "the commands")
        await driver.aclose()
        await robot.wait_for(lambda: robot.twists[-1] == STOP, "the stop")
        with anyio.fail_after(20):  # the status follows (at most every STATUS_INTERVAL_S)
            while True:
                published = await watcher.expect(is_op("publish", topic=STATUS_TOPIC))
                status = json.loads(published["msg"]["data"])
                if [e["kind"] for e in status["events"]][-1:] == ["deadman_stop"]:
                    break
    lines = [r.getMessage() for r in caplog.records if r.name == "rwt.safety"]
    clamps = [line for line in lines if line.startswith("event=safety_clamp ")]
    assert len(clamps) == 1  # one line for the episode of three
    assert clamps[0].startswith("event=safety_clamp client=tcp:127.0.0.1:")
    assert " frontend=rosbridge target=/cmd_vel field=linear.x value=2.0" in clamps[0]
    assert " bound=[-0.5,0.5] detail='sent 0.5'" in clamps[0]
    rejects = [line for line in lines if line.startswith("event=safety_reject ")]
    assert len(rejects) == 1 and "field=data value=-1.0 bound=[0,3.14]" in rejects[0]
    stops = [line for line in lines if line.startswith("event=safety_deadman_stop ")]
    assert len(stops) == 1 and "detail='its connection ended'" in stops[0]

    assert [rule["name"] for rule in status["topics"]] == ["/cmd_vel", "/arm/joint_cmd"]
    assert status["topics"][0]["bounds"] == {"linear.x": [-0.5, 0.5], "angular.z": [-1.0, 1.0]}
    assert status["topics"][0]["deadman_s"] == 0.5 and status["topics"][0]["approval"] is True
    kinds = [(e["kind"], e["target"], e["count"]) for e in status["events"]]
    assert kinds == [
        ("clamp", "/cmd_vel", 3),
        ("reject", "/arm/joint_cmd", 1),
        ("deadman_stop", "/cmd_vel", 1),
    ]


async def test_version_lists_the_envelope() -> None:
    robot = Robot.make()
    async with running_server(ServerConfig(host="127.0.0.1"), graph=robot.graph) as harness:
        url = harness.server.urls["websocket"].replace("ws://", "http://")
        async with httpx.AsyncClient(base_url=url, timeout=20) as http:
            answer = (await http.get("/version")).json()
    assert answer["rwt"]["safety"] is True
    assert "/cmd_vel" not in json.dumps(answer)  # it names no topic (D49)
