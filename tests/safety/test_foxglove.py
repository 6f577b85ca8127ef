"""The envelope binds Foxglove's client publish, in JSON and in CDR, as it binds rosbridge.

The real Foxglove client in Node (@foxglove/ws-protocol, tests/js/safety_foxglove.mjs)
advertises ``/cmd_vel`` in CDR and in JSON on a server with the example's rules and
sends Twists out of bounds: the robot gets them clamped, the client one warning
status for the episode; a NaN in CDR, a joint command out of bounds and a second
advertise of ``/cmd_vel`` with another type are refused with an error status each,
and nothing of them reaches the robot (docs/safety.md, D67).
"""

from __future__ import annotations

from collections.abc import AsyncIterator

import anyio
import pytest

from rwt import RosbridgeServer, ServerConfig
from tests.foxglove import extras
from tests.safety.example import Robot

pytestmark = [pytest.mark.anyio, pytest.mark.node]


@pytest.fixture
async def served() -> AsyncIterator[tuple[Robot, str]]:
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)
    robot = Robot.make()
    server = RosbridgeServer(robot.graph, ServerConfig(host="127.0.0.1", port=0))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield robot, url
        server.stop()


async def test_client_publish_in_cdr_and_json_is_held_to_the_bounds(
    served: tuple[Robot, str],
) -> None:
    robot, url = served
    command = extras.command("commands", url, script="safety_foxglove.mjs")
    with anyio.fail_after(120):
        done = await anyio.run_process(command, cwd=extras.JS_DIR, check=False)
    assert done.returncode == 0, done.stderr.decode()
    statuses = extras.result_of(done.stdout.decode())["statuses"]
    warnings = [s["message"] for s in statuses if s["level"] == 1]
    errors = [s["message"] for s in statuses if s["level"] == 2]
    assert len(warnings) == 1
    assert "linear.x 2 clamped to 0.5 (bound [-0.5, 0.5])" in warnings[0]
    assert "angular.z -5 clamped to -1 (bound [-1, 1])" in warnings[0]
    assert any("linear.x is NaN, not a finite number" in text for text in errors)
    assert any("data 9 is outside [0, 3.14]" in text for text in errors)
    assert any("established with type geometry_msgs/msg/Twist" in text for text in errors)
    await robot.wait_for(lambda: len(robot.cmd_vel) >= 3 and robot.joint, "the commands")
    assert [(m["linear"]["x"], m["angular"]["z"]) for m in robot.twists] == [
        (0.5, -1.0),
        (0.5, 0.25),
        (0.0, 0.0),  # the dead-man's stop: the client closed while it commanded
    ]
    assert robot.joint == [1.0]
