"""Dead-man stops: a commander that goes quiet, or goes, gets the topic's stop once.

While a remote client has published ``/cmd_vel`` within ``deadman_s`` (0.5 s in the
example) the topic is commanded; when no command came for ``deadman_s``, or the last
commander's connection ends, the envelope publishes ``stop`` once (docs/safety.md,
D68). The tests look at what the robot's subscriber hears: the commands, then the
stop after them, and nothing after it; how soon it comes is a benchmark's
(benchmarks/deadman.py), not these tests'. Real clients: roslibpy, a WebSocket
client, an aiortc WebRTC peer, and HTTP requests, whose end is no connection's end.
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator

import anyio
import httpx
import pytest

from rwt import ServerConfig
from tests.safety.example import STOP, Robot, twist
from tests.support.clients import HAS_AIORTC, Client, Harness, running_server
from tests.support.realclients import run_python

pytestmark = pytest.mark.anyio

RATE_S = 0.1  # a teleop's 10 Hz


@pytest.fixture
async def served() -> AsyncIterator[tuple[Robot, Harness]]:
    robot = Robot.make()
    async with running_server(ServerConfig(host="127.0.0.1"), graph=robot.graph) as harness:
        yield robot, harness


async def _drive(client: Client, count: int, x: float = 0.2) -> None:
    """``count`` Twists at 10 Hz, as a teleop sends them."""
    for _ in range(count):
        await client.send({"op": "publish", "topic": "/cmd_vel", "msg": twist(x)})
        await anyio.sleep(RATE_S)


def _stops(robot: Robot) -> list[int]:
    return [index for index, msg in enumerate(robot.twists) if msg == STOP]


async def test_a_quiet_commander_gets_the_stop_once(served: tuple[Robot, Harness]) -> None:
    robot, harness = served
    client = await harness.connect("ws")
    await client.send({"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist"})
    await _drive(client, 10)
    await robot.wait_for(lambda: _stops(robot), "the stop")
    assert robot.twists[:10] == [twist(0.2)] * 10
    assert _stops(robot) == [10]  # after the last command: the commander is still connected
    await _drive(client, 3, x=0.1)  # commanded again: a new run, its own stop
    await robot.wait_for(lambda: len(_stops(robot)) == 2, "the second stop")
    assert robot.twists[11:] == [twist(0.1)] * 3 + [STOP]
    await anyio.sleep(1.0)  # nothing more: the stop is published once a run
    assert len(robot.twists) == 15


@pytest.mark.parametrize("transport", ["ws", "tcp", *(["webrtc"] if HAS_AIORTC else [])])
async def test_a_commander_that_goes_gets_the_stop(
    served: tuple[Robot, Harness], transport: str
) -> None:
    robot, harness = served
    client = await harness.connect(transport)
    await client.send({"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist"})
    await _drive(client, 5)
    await robot.wait_for(lambda: len(robot.twists) == 5, "the commands")
    closed = anyio.current_time()
    await client.aclose()
    await robot.wait_for(lambda: _stops(robot), "the stop")
    assert robot.twists == [twist(0.2)] * 5 + [STOP]
    assert robot.cmd_vel[-1][0] >= closed  # it came after the close


async def test_a_second_commander_keeps_it_alive(served: tuple[Robot, Harness]) -> None:
    robot, harness = served
    first, second = await harness.connect("ws", "first"), await harness.connect("tcp", "second")
    for client in (first, second):
        advertise = {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist"}
        await client.send(advertise)
    async with anyio.create_task_group() as tg:
        tg.start_soon(_drive, first, 5, 0.2)
        tg.start_soon(_drive, second, 15, 0.3)
        await anyio.sleep(6 * RATE_S)
        await first.aclose()  # the second still commands: no stop now
    await robot.wait_for(lambda: _stops(robot), "the stop")
    assert _stops(robot) == [len(robot.twists) - 1]  # one stop, after the last command
    assert robot.twists.count(twist(0.3)) == 15


async def test_an_http_command_stands_for_deadman_s() -> None:
    """A request is one command: its end is not a commander leaving (D68)."""
    robot = Robot.make()
    async with running_server(ServerConfig(host="127.0.0.1"), graph=robot.graph) as harness:
        url = harness.server.urls["websocket"].replace("ws://", "http://")
        async with httpx.AsyncClient(base_url=url, timeout=20) as http:
            answer = await http.post("/api/topics/cmd_vel", json=twist(0.3))
        assert answer.status_code == 200
        await robot.wait_for(lambda: _stops(robot), "the stop")
    (commanded, _), (stopped, stop) = robot.cmd_vel
    assert stop == STOP
    assert stopped - commanded >= 0.45  # not at the request's end: deadman_s after it


async def test_roslibpy_quiet_then_gone() -> None:
    """roslibpy at 10 Hz, quiet while connected, then again and it terminates."""
    robot = Robot.make()
    async with running_server(ServerConfig(host="127.0.0.1"), graph=robot.graph) as harness:
        port = harness.port("websocket")
        await run_python(
            f"""
            import time, roslibpy
            ros = roslibpy.Ros("127.0.0.1", {port})
            ros.run(timeout=10)
            topic = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/Twist")
            topic.advertise()
            for _ in range(10):
                topic.publish(roslibpy.Message({json.dumps(twist(2.0, -5.0))}))
                time.sleep(0.1)
            time.sleep(1.5)  # quiet, still connected
            for _ in range(3):
                topic.publish(roslibpy.Message({json.dumps(twist(0.1))}))
                time.sleep(0.1)
            ros.terminate()
            """
        )
        await robot.wait_for(lambda: len(_stops(robot)) == 2, "both stops")
    clamped = twist(0.5, -1.0)
    assert robot.twists == [clamped] * 10 + [STOP] + [twist(0.1)] * 3 + [STOP]
