"""roslibpy 2.1.0 sends a ``publish`` with ``type`` without advertising (D48, REF §13.3).

roslibpy's ``Topic.publish`` advertises first, so the script sends the raw op, as a
protocol 2.0.0 client (rosbridge_suite 2.6.0, 3.2.0, 4.1.0) may. The op is latched:
by default it advertises the topic and a later subscriber gets the message; with
``--compat rosbridge-2.1`` it is refused, and the subscriber gets only what comes
after it subscribed (the topic's type then known from the subscription).
"""

from __future__ import annotations

import json

import pytest

from rwt_protocol.server.compat import Compat
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.support.clients import running_server
from tests.support.realclients import run_python

pytestmark = pytest.mark.anyio

SCENARIO = """
import json, threading
import roslibpy

def raw_publish(ros, data):
    ros.send_on_ready(roslibpy.Message({{
        "op": "publish", "topic": "/greeting", "type": "std_msgs/String", "id": "p1",
        "latch": True, "msg": {{"data": data}},
    }}))

def scenario(port):
    pub, sub = roslibpy.Ros("127.0.0.1", port), roslibpy.Ros("127.0.0.1", port)
    pub.run(timeout=20)
    sub.run(timeout=20)
    raw_publish(pub, "before")
    type_name = pub.get_topic_type("/greeting")  # its reply: the publish was handled
    got, second = [], threading.Event()
    def take(msg):
        got.append(msg["data"])
        if msg["data"] == "after":
            second.set()
    roslibpy.Topic(sub, "/greeting", "std_msgs/String").subscribe(take)
    sub.get_topics()  # its reply: the subscription is in place
    raw_publish(pub, "after")
    second.wait(20)
    return {{"type": type_name, "got": got}}, pub

results = [scenario(port) for port in {ports}]
print(json.dumps([result for result, _ in results]), flush=True)
results[0][1].terminate()  # the first to run started twisted's reactor, which all share
"""


async def test_roslibpy_publish_with_type_advertises_unless_compat_2_1() -> None:
    compat = ServerConfig(session=SessionConfig(compat=Compat.ROSBRIDGE_2_1))
    async with running_server() as default, running_server(compat) as old:
        ports = [default.port("websocket"), old.port("websocket")]
        out = await run_python(SCENARIO.format(ports=ports))
    assert json.loads(out) == [
        {"type": "std_msgs/msg/String", "got": ["before", "after"]},
        {"type": "", "got": ["after"]},
    ]
