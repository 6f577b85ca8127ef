"""``rwt serve --ros2 --compat rosbridge``: rosbridge_suite's clients on a real ROS 2 graph.

roslibpy 2.1.0 logs a traceback for each ``status`` op, and clients match
rosbridge_suite's texts (docs/differences.md, "Drop-in mode"). Here the graph has a
real rclpy node, and the call to a service nobody offers first waits for the link's
discovery: its late failure is in rosbridge_suite's words too.
"""

from __future__ import annotations

import json
import subprocess
import sys
from typing import TYPE_CHECKING

import pytest

from tests.integration.client_harness import ServerProcess, node_missing_reason
from tests.integration.test_compat_roslibpy import REFUSED_OPS
from tests.support.realclients import run_node

from .support import Peer, serve_ros2, skip_without_rclpy

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

COMPAT = ("--compat", "rosbridge")


@pytest.fixture(scope="module")
def server(ros_env: Path) -> Iterator[ServerProcess]:
    """One `rwt serve --ros2 --compat rosbridge` for the module."""
    process = serve_ros2(ros_env, *COMPAT)
    try:
        yield process
    finally:
        process.stop()


def test_roslibpy_logs_no_traceback_on_a_ros2_graph(server: ServerProcess) -> None:
    # the module's server: the refused ops touch nothing beyond their own connection
    script = REFUSED_OPS.format(port=server.port)
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True
    )
    assert json.loads(done.stdout) == {"failed": ["Service /nope does not exist"]}
    assert "Traceback" not in done.stderr, done.stderr


ROSLIB = """
import * as ROSLIB from "roslib";
const ros = new ROSLIB.Ros({ url: "ws://127.0.0.1:PORT" });
const statuses = [];
const emit = ros.emit.bind(ros);
ros.emit = (name, ...args) => {  // every status roslib receives, with an id or not
  if (String(name).startsWith("status")) statuses.push(args[0]);
  return emit(name, ...args);
};
setTimeout(() => { console.log(JSON.stringify({ timeout: statuses })); process.exit(1); }, 40000);
const call = (name, request, timeout) => new Promise((resolve) => {
  new ROSLIB.Service({ ros, name, serviceType: "std_srvs/srv/SetBool" })
    .callService(request, (r) => resolve({ ok: r }), (e) => resolve({ error: e }), timeout);
});
const wait = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
const until = async (check, ms) => {  // poll every 50 ms, at most ms
  for (const end = Date.now() + ms; !check() && Date.now() < end;) await wait(50);
};
const refuse = () => {
  new ROSLIB.Topic({ ros, name: "/a", messageType: "no_such_pkg/msg/Nope" }).subscribe(() => {});
  const b = new ROSLIB.Topic({ ros, name: "/b", messageType: "std_msgs/msg/String" });
  b.publish({ data: 1 });
  ros.callOnConnection({ op: "no_such_op" });
};
refuse();
// a real rclpy server, waited for up to the call's timeout while the link discovers it
const answered = await call("/compat_switch", { data: true }, 20);
const missing = await call("/nobody_serves", { data: true });  // after the discovery wait
await wait(500);  // any status sent meanwhile arrives
const silent = statuses.length;
ros.setStatusLevel("error");
refuse();
await until(() => statuses.length >= silent + 3, 20000);  // the three refusals' statuses
console.log(JSON.stringify({ answered, missing, silent, asked: statuses.length }));
ros.close();
process.exit(0);
"""


@pytest.mark.node
@pytest.mark.skipif(node_missing_reason() is not None, reason=str(node_missing_reason()))
async def test_roslib_in_node_gets_rosbridges_texts_and_statuses_only_when_asked(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("serve", "/compat_switch", ros_env):
        out = await run_node(ROSLIB.replace("PORT", str(server.port)))
    got = json.loads(out.strip().splitlines()[-1])
    assert got["answered"] == {"ok": {"success": True, "message": "ros2 got True"}}
    assert got["missing"] == {"error": "Service /nobody_serves does not exist"}
    assert got["silent"] == 0  # rosbridge_suite sends none unless asked
    assert got["asked"] >= 3  # after set_level: the subscribe, publish and op refused
