"""Actions between a real rclpy action server and rosbridge clients through `rwt serve --ros2`."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
from pathlib import Path

import anyio
import pytest

from tests.integration.client_harness import JS_DIR, ServerProcess, node_missing_reason
from tests.support.realclients import run_python

from .support import Peer, roslibpy_prelude, skip_without_rclpy

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

GOAL = """
client = roslibpy.ActionClient(ros, "{action}", "test_msgs/action/Fibonacci")
servers = roslibpy.Service(ros, "/rosapi/action_servers", "rosapi_msgs/srv/GetActionServers")
request = roslibpy.ServiceRequest({{}})
listed = wait_for(lambda: "{action}" in servers.call(request)["action_servers"])
feedback, results, errors = [], [], []
goal = roslibpy.Goal({{"order": {order}}})
goal_id = client.send_goal(goal, results.append, feedback.append, errors.append)
wait_for(lambda: results or errors or len(feedback) >= {cancel_after})
if {cancel_after} and not results:
    client.cancel_goal(goal_id)
wait_for(lambda: results or errors)
out = {{
    "listed": listed,
    "feedback": [dict(f) for f in feedback],
    "results": [dict(r) for r in results],
    "errors": [str(e) for e in errors],
}}
print(json.dumps(out, default=lambda o: getattr(o, "value", str(o))))
ros.terminate()
"""


async def _goal(server: ServerProcess, action: str, order: int, cancel_after: int) -> dict:
    script = GOAL.format(action=action, order=order, cancel_after=cancel_after)
    out = await run_python(roslibpy_prelude(server.port) + script)
    return json.loads(out.strip().splitlines()[-1])


async def test_roslibpy_drives_a_ros2_action_server(server: ServerProcess, ros_env: Path) -> None:
    with Peer("fibonacci", "/fibonacci", ros_env) as peer:
        out = await _goal(server, "/fibonacci", 5, 0)
        assert peer.next() == {"goal": 5}
    assert out["listed"] is True  # rosapi lists the ROS 2 action server
    assert [f["sequence"] for f in out["feedback"]] == [
        [0, 1, 1],
        [0, 1, 1, 2],
        [0, 1, 1, 2, 3],
        [0, 1, 1, 2, 3, 5],
    ]
    [result] = out["results"]
    assert result["values"] == {"sequence": [0, 1, 1, 2, 3, 5]}
    assert result["status"] == 4  # SUCCEEDED


async def test_roslibpy_cancels_a_ros2_goal(server: ServerProcess, ros_env: Path) -> None:
    with Peer("fibonacci", "/fibonacci_long", ros_env):
        out = await _goal(server, "/fibonacci_long", 200, 2)
    [result] = out["results"]
    assert result["status"] == 5  # CANCELED
    assert 2 <= len(out["feedback"]) < 199


ADVERTISE_IN_NODE = """
import * as ROSLIB from "roslib";
const ros = new ROSLIB.Ros({{ url: "ws://127.0.0.1:{port}" }});
const action = new ROSLIB.Action({{
  ros, name: "/web_fibonacci", actionType: "test_msgs/action/Fibonacci",
}});
action.advertise(
  (goal, id) => {{
    const sequence = [0, 1];
    for (let i = 1; i < goal.order; i++) {{
      sequence.push(sequence.at(-1) + sequence.at(-2));
      action.sendFeedback(id, {{ sequence: [...sequence] }});
    }}
    action.setSucceeded(id, {{ sequence }});
    console.log(JSON.stringify({{ goal }}));
  }},
  () => {{}},
);
setTimeout(() => process.exit(0), 20000);
process.stdin.on("data", () => process.exit(0));
"""


@pytest.mark.node
@pytest.mark.skipif(node_missing_reason() is not None, reason=str(node_missing_reason()))
async def test_a_ros2_action_client_drives_an_action_roslib_advertised(
    server: ServerProcess, ros_env: Path
) -> None:
    script = JS_DIR / f".rwt-ros2-action-{os.getpid()}.mjs"
    script.write_text(ADVERTISE_IN_NODE.format(port=server.port), "utf-8")
    try:
        async with await anyio.open_process(
            [shutil.which("node") or "node", str(script)], cwd=JS_DIR
        ) as provider:
            try:
                with Peer("send_goal", "/web_fibonacci", ros_env) as client:
                    lines = [await anyio.to_thread.run_sync(client.next)]
                    while "feedback" in lines[-1] and len(lines) < 5:
                        lines.append(await anyio.to_thread.run_sync(client.next))
            finally:
                with contextlib.suppress(ProcessLookupError):
                    provider.kill()
    finally:
        script.unlink(missing_ok=True)
    *feedback, result = lines
    assert result == {"result": [0, 1, 1, 2, 3], "status": 4}  # SUCCEEDED
    # feedback travels on a topic, the result as a service reply: the last feedback
    # may come after the result (the client then stops listening), never out of order
    expected = [{"feedback": [0, 1, 1]}, {"feedback": [0, 1, 1, 2]}, {"feedback": [0, 1, 1, 2, 3]}]
    assert feedback == expected[: len(feedback)]
