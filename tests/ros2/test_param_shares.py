"""A real rclpy node declaring more parameters than its share cannot fill the store."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import pytest

from rwt_graph.parameters.store import Parameters
from tests.support.realclients import run_python

from .support import peers, roslibpy_prelude, skip_without_rclpy

if TYPE_CHECKING:
    from pathlib import Path

    from tests.integration.client_harness import ServerProcess

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

SHARE = Parameters().max_node_params  # the store `rwt serve` makes has the default share
CROWD = SHARE + 500

BYSTANDER = """
SHARE = {share}
names = roslibpy.Service(ros, "/rosapi/get_param_names", "rosapi_msgs/srv/GetParamNames")

def listed():
    return names.call(roslibpy.ServiceRequest({{}}), timeout=20)["names"]

def crowded():
    return [name for name in listed() if name.startswith("/crowded:")]

copied = wait_for(lambda: len(crowded()) >= SHARE, 60)
other = wait_for(lambda: "/robot_params:speed" in listed(), 60)
# the node changes p00000 every 50 ms: four values seen are three refreshes of the copy
ticking = roslibpy.Param(ros, "/crowded:p00000")
seen = set()
wait_for(lambda: seen.add(ticking.get(timeout=20)) or len(seen) >= 4, 60)
gain = roslibpy.Param(ros, "/rosbridge_websocket:gain")  # a client's, on a node the graph has
gain.set(2.5, timeout=20)
mine = crowded()
numbered = sorted(name for name in mine if name.startswith("/crowded:p"))
print(json.dumps({{
    "copied": copied,
    "refreshes": len(seen) >= 4,
    "count": len(mine),
    "first": numbered == [f"/crowded:p{{n:05}}" for n in range(len(numbered))],
    "numbered": len(numbered) >= SHARE - 10,
    "gain": gain.get(timeout=20),
    "other": [other, roslibpy.Param(ros, "/robot_params:speed").get(timeout=20)],
}}))
ros.terminate()
"""


async def test_a_node_past_its_share_leaves_the_store_to_others_and_logs_once(
    server: ServerProcess, ros_env: Path
) -> None:
    script = roslibpy_prelude(server.port) + BYSTANDER.format(share=SHARE)
    with peers(ros_env, ("many_params", "crowded", str(CROWD)), ("params", "robot_params")):
        out = json.loads((await run_python(script)).splitlines()[-1])
    # its first SHARE parameters by its listing's order (rclpy's own, use_sim_time
    # and the like, then p00000, p00001, ...), while a client's set and another
    # node's copy go on as before
    assert out == {
        "copied": True,
        "refreshes": True,
        "count": SHARE,
        "first": True,
        "numbered": True,
        "gain": 2.5,
        "other": [True, 1.5],
    }
    log = server.stderr_text()
    # one line for the episode, however many refreshes saw the node past its share
    assert log.count("event=param_copy_partial node=/crowded") == 1, log[-3000:]
    assert f"node=/crowded held={SHARE} left_out=" in log
    assert "replacing" not in log and "Traceback" not in log, log[-3000:]
