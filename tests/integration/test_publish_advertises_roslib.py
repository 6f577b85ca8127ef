"""roslib 2.x (roslibjs, in Node) publishes without advertising (D48, REF §13.3).

roslib 2.1.0's ``Topic.publish`` advertises first and sends no ``type``, so the page
sends the op itself through ``Ros.callOnConnection``, as a page written for protocol
2.0.0 (rosbridge_suite 2.6.0, 3.2.0, 4.1.0) may: a latched ``publish`` with ``type``
to a topic nobody advertised. By default it advertises the topic, and a second roslib
connection that subscribes later gets it, then the next one. With ``--compat
rosbridge-2.1`` it is refused with an error status for its id (asked for with
``setStatusLevel``, as rosbridge modes send none unasked), and the subscriber gets
only what comes after it subscribed (the topic's type then known from the
subscription). One Node process drives both servers.
"""

from __future__ import annotations

import json

import pytest

from rwt_protocol.server.compat import Compat
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.support.clients import running_server
from tests.support.realclients import node_missing, run_node

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.node,
    pytest.mark.skipif(node_missing() is not None, reason=str(node_missing())),
]

SCENARIO = """
import * as ROSLIB from "roslib";

const ask = (call) => new Promise((resolve, reject) => call(resolve, reject));

async function scenario(port) {
  const url = `ws://127.0.0.1:${port}`;
  const pub = new ROSLIB.Ros({ url }), sub = new ROSLIB.Ros({ url });
  const refused = [];
  pub.on("status:p1", (status) => refused.push(status.level));
  pub.setStatusLevel("error");
  const publish = (data) => pub.callOnConnection({
    op: "publish", topic: "/greeting", type: "std_msgs/String", id: "p1", latch: true,
    msg: { data },
  });
  publish("before");
  // its reply comes after the publish was handled
  const type = await ask((ok, fail) => pub.getTopicType("/greeting", ok, fail));
  const got = [];
  let second;
  const after = new Promise((resolve) => { second = resolve; });
  const topic = new ROSLIB.Topic({ ros: sub, name: "/greeting", messageType: "std_msgs/String" });
  topic.subscribe((msg) => { got.push(msg.data); if (msg.data === "after") second(); });
  await ask((ok, fail) => sub.getTopics(ok, fail));  // the subscription is in place
  publish("after");
  await after;
  pub.close();
  sub.close();
  return { type, got, refused };
}

const timer = setTimeout(() => { console.error("timed out"); process.exit(2); }, 30000);
const results = [];
for (const port of PORTS) results.push(await scenario(port));
clearTimeout(timer);
console.log(JSON.stringify(results));
"""


async def test_roslib_publish_with_type_advertises_unless_compat_2_1() -> None:
    compat = ServerConfig(session=SessionConfig(compat=Compat.ROSBRIDGE_2_1))
    async with running_server() as default, running_server(compat) as old:
        ports = [default.port("websocket"), old.port("websocket")]
        out = await run_node(SCENARIO.replace("PORTS", json.dumps(ports)))
    assert json.loads(out.strip().splitlines()[-1]) == [
        {"type": "std_msgs/msg/String", "got": ["before", "after"], "refused": []},
        {"type": "", "got": ["after"], "refused": ["error"]},
    ]
