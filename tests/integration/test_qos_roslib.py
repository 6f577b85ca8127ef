"""roslib 2.x (roslibjs, in Node) sends protocol 2.1.0's ``qos`` (D62-D64), as its users would.

roslib 2.1.0's ``Topic`` has no ``qos`` option, so the page sends the ops with one
through ``Ros.callOnConnection`` and takes a topic's messages with ``Ros.on(topic)``,
as a page written for rosbridge_suite 3.3 does; its ``Topic.publish`` then publishes
on the topic (its own advertise, without ``qos``, shares the topic's). A
transient-local topic of depth 5: late subscribers get its last five in order, a
volatile one nothing. A bad ``qos`` gets an error status naming the field (asked
for with ``setStatusLevel``) and registers nothing; a reliable subscription of a
best-effort topic is warned and gets nothing, one asking ``best_available`` gets
the messages. After the server's clock moves on (an in-process service moves it, so
nothing waits), a kept message past its lifespan is no longer given, a fresh one is.
"""

from __future__ import annotations

import json
import time

import pytest

import rwt
from tests.support.clients import running_server
from tests.support.realclients import node_missing, run_node

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.node,
    pytest.mark.skipif(node_missing() is not None, reason=str(node_missing())),
]

SCENARIO = """
import * as ROSLIB from "roslib";

const url = `ws://127.0.0.1:PORT`;
const ask = (call) => new Promise((resolve, reject) => call(resolve, reject));
const connect = async () => {
  const ros = new ROSLIB.Ros({ url });
  await new Promise((resolve) => ros.on("connection", resolve));
  return ros;
};
// the messages of topic that came until the server answered a call sent after subscribing
async function collect(ros, topic, qos) {
  const got = [];
  ros.on(topic, (message) => got.push(message.msg.data));
  ros.callOnConnection({ op: "subscribe", topic, qos });
  await ask((ok, fail) => ros.getTopics(ok, fail));
  return [...got];
}

const timer = setTimeout(() => { console.error("timed out"); process.exit(2); }, 30000);
const pub = await connect();
const statuses = [];
pub.on("status:bad", (status) => statuses.push(status));
pub.setStatusLevel("warning");
pub.callOnConnection({
  op: "advertise", topic: "/map", type: "std_msgs/String",
  qos: { durability: "transient_local", depth: 5, lifespan: 5 },
});
const map = new ROSLIB.Topic({ ros: pub, name: "/map", messageType: "std_msgs/String" });
for (let i = 0; i < 8; i++) map.publish({ data: `m${i}` });
pub.callOnConnection({
  op: "advertise", topic: "/other", type: "std_msgs/String", id: "bad",
  qos: { depth: 5, reliability: "fast" },
});
pub.callOnConnection({
  op: "advertise", topic: "/scan", type: "std_msgs/String", qos: { reliability: "best_effort" },
});
const otherType = await ask((ok, fail) => pub.getTopicType("/other", ok, fail));

const late = await connect(), volatile = await connect(), reliable = await connect();
const warned = [];
reliable.on("status", (status) => warned.push(status.level));
reliable.setStatusLevel("warning");
const result = {
  late: await collect(late, "/map", { durability: "transient_local" }),
  volatile: await collect(volatile, "/map", { durability: "volatile" }),
  statuses: statuses.map((s) => [s.level, s.msg]),
  otherType,
};
await collect(reliable, "/scan", { reliability: "reliable" });
const matched = await connect();
await collect(matched, "/scan", { reliability: "best_available" });
const scanned = [];
for (const ros of [reliable, matched]) {
  const got = [];
  ros.on("/scan", (message) => got.push(message.msg.data));
  scanned.push(got);
}
const scan = new ROSLIB.Topic({ ros: pub, name: "/scan", messageType: "std_msgs/String" });
scan.publish({ data: "s" });
await ask((ok, fail) => pub.getTopics(ok, fail));
for (const ros of [reliable, matched]) await ask((ok, fail) => ros.getTopics(ok, fail));
result.scan = { reliable: scanned[0], best_available: scanned[1], warned };

const age = new ROSLIB.Service({ ros: pub, name: "/test/age", serviceType: "std_srvs/Trigger" });
await ask((ok, fail) => age.callService({}, ok, fail));
map.publish({ data: "fresh" });
await ask((ok, fail) => pub.getTopics(ok, fail));
result.after_lifespan = await collect(await connect(), "/map", { durability: "transient_local" });
clearTimeout(timer);
console.log(JSON.stringify(result));
process.exit(0);
"""


class Ahead:
    """The real clocks plus ``offset`` seconds (an ``rwt.Clock``)."""

    def __init__(self) -> None:
        self.offset = 0.0

    def monotonic(self) -> float:
        return time.monotonic() + self.offset

    def wall(self) -> float:
        return time.time() + self.offset


async def test_roslib_sends_qos_and_gets_what_it_asked() -> None:
    clock = Ahead()
    graph = rwt.Graph(clock=clock)

    def age(_request: dict[str, object]) -> dict[str, object]:
        clock.offset += 60  # every kept message is past its 5 s lifespan now
        return {"success": True}

    graph.create_service("/test/age", "std_srvs/srv/Trigger", age)
    async with running_server(graph=graph) as server:
        out = await run_node(SCENARIO.replace("PORT", str(server.port("websocket"))))
    result = json.loads(out.strip().splitlines()[-1])
    assert result["late"] == ["m3", "m4", "m5", "m6", "m7"]
    assert result["volatile"] == []
    assert result["statuses"] == [
        [
            "error",
            "advertise: expected one of 'reliable', 'best_effort' or 'best_available',"
            " got 'fast' at $.qos.reliability",
        ]
    ]
    assert result["otherType"] == ""  # nothing registered
    assert result["scan"] == {"reliable": [], "best_available": ["s"], "warned": ["warning"]}
    assert result["after_lifespan"] == ["fresh"]
