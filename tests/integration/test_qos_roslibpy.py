"""roslibpy 2.1.0 sends protocol 2.1.0's ``qos`` (D62-D63), as its users would.

roslibpy's ``Topic`` has no ``qos`` argument, so the script sends the ops with one
itself (``Ros.send_on_ready``) and takes messages with ``Ros.on(topic)``, as a roslibpy
program written for rosbridge_suite 3.3 does; its ``Topic.publish`` then publishes on
the topic (its own advertise, without ``qos``, shares the topic's). One connection
makes a transient-local topic of depth 5 with a lifespan and publishes; late
subscribers get its last five in order, a volatile one nothing; after the server's
clock moves on (an in-process service of the test's graph moves it, so nothing
waits), a kept message past its lifespan is no longer given, a fresh one is.
"""

from __future__ import annotations

import json
import time

import pytest

import rwt
from tests.support.clients import running_server
from tests.support.realclients import run_python

pytestmark = pytest.mark.anyio

SCENARIO = """
import json, threading
import roslibpy

def collect(ros, topic, qos, expect):
    got, done = [], threading.Event()
    def take(msg):
        got.append(msg["data"])
        if len(got) == expect:
            done.set()
    ros.on(topic, take)
    ros.send_on_ready(roslibpy.Message({{"op": "subscribe", "topic": topic, "qos": qos}}))
    ros.get_topics()  # its reply comes after the subscription's first messages
    if expect:
        done.wait(20)
    return list(got)  # what came so far (later messages still come to ``got``)

pub = roslibpy.Ros("127.0.0.1", {port})
pub.run(timeout=20)
qos = {{"durability": "transient_local", "depth": 5, "lifespan": 5}}
pub.send_on_ready(roslibpy.Message({{
    "op": "advertise", "topic": "/map", "type": "std_msgs/String", "qos": qos,
}}))
topic = roslibpy.Topic(pub, "/map", "std_msgs/String")
for i in range(8):
    topic.publish(roslibpy.Message({{"data": "m%d" % i}}))
pub.get_topics()  # its reply: every publish was handled

late, volatile = roslibpy.Ros("127.0.0.1", {port}), roslibpy.Ros("127.0.0.1", {port})
late.run(timeout=20)
volatile.run(timeout=20)
results = {{
    "late": collect(late, "/map", {{"durability": "transient_local"}}, 5),
    "volatile": collect(volatile, "/map", {{"durability": "volatile"}}, 0),
}}
roslibpy.Service(pub, "/test/age", "std_srvs/Trigger").call(roslibpy.ServiceRequest())
topic.publish(roslibpy.Message({{"data": "fresh"}}))
pub.get_topics()
later = roslibpy.Ros("127.0.0.1", {port})
later.run(timeout=20)
results["after_lifespan"] = collect(later, "/map", {{"durability": "transient_local"}}, 1)
print(json.dumps(results), flush=True)
pub.terminate()
"""


class Ahead:
    """The real clocks plus ``offset`` seconds (an ``rwt.Clock``)."""

    def __init__(self) -> None:
        self.offset = 0.0

    def monotonic(self) -> float:
        return time.monotonic() + self.offset

    def wall(self) -> float:
        return time.time() + self.offset


async def test_roslibpy_sends_qos_and_gets_transient_local_and_lifespan() -> None:
    clock = Ahead()
    graph = rwt.Graph(clock=clock)

    def age(_request: dict[str, object]) -> dict[str, object]:
        clock.offset += 60  # every kept message is past its 5 s lifespan now
        return {"success": True}

    graph.create_service("/test/age", "std_srvs/srv/Trigger", age)
    async with running_server(graph=graph) as server:
        out = await run_python(SCENARIO.format(port=server.port("websocket")))
    assert json.loads(out) == {
        "late": ["m3", "m4", "m5", "m6", "m7"],
        "volatile": [],
        "after_lifespan": ["fresh"],
    }
