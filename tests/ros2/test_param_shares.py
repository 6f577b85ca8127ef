"""A real rclpy node declaring more parameters than its share cannot fill the store."""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING

import pytest
from websockets.sync.client import ClientConnection, connect

from rwt_graph.parameters.store import Parameters
from tests.support.realclients import run_python

from .support import peers, roslibpy_prelude, skip_without_rclpy

if TYPE_CHECKING:
    from pathlib import Path

    from tests.integration.client_harness import ServerProcess

pytestmark = [skip_without_rclpy()]

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
# the node changes p00000 every 50 ms: three values seen are two refreshes of the copy
ticking = roslibpy.Param(ros, "/crowded:p00000")
seen = set()
wait_for(lambda: seen.add(ticking.get(timeout=20)) or len(seen) >= 3, 60)
gain = roslibpy.Param(ros, f"{{own_node()}}:gain")  # a client's, on its own node (D34)
gain.set(2.5, timeout=20)
mine = crowded()
numbered = sorted(name for name in mine if name.startswith("/crowded:p"))
print(json.dumps({{
    "copied": copied,
    "refreshes": len(seen) >= 3,
    "count": len(mine),
    "first": numbered == [f"/crowded:p{{n:05}}" for n in range(len(numbered))],
    "numbered": len(numbered) >= SHARE - 10,
    "gain": gain.get(timeout=20),
    "other": [other, roslibpy.Param(ros, "/robot_params:speed").get(timeout=20)],
}}))
ros.terminate()
"""


@pytest.mark.anyio
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


def _has(ws: ClientConnection, name: str, call_id: str) -> bool:
    call = {"op": "call_service", "service": "/rosapi/has_param", "args": {"name": name}}
    ws.send(json.dumps({**call, "id": call_id}))
    while True:
        reply = json.loads(ws.recv(timeout=20))
        if reply.get("id") == call_id:
            return bool(reply["values"]["exists"])


def test_a_bystander_is_answered_while_thousands_of_parameters_load(
    server: ServerProcess, ros_env: Path
) -> None:
    first, late = "/loading:p00000", "/loading:p02000"  # both within the node's share
    partial = 0  # answers that saw the copy begun and not yet done
    calls = 0
    with (
        connect(f"ws://127.0.0.1:{server.port}", max_size=None) as ws,
        peers(ros_env, ("many_params", "loading", str(CROWD))),
    ):
        end = time.monotonic() + 60
        while time.monotonic() < end:
            calls += 1
            if not _has(ws, first, f"f{calls}"):
                continue
            if _has(ws, late, f"l{calls}"):
                break
            partial += 1  # p00000 was there, and p02000 still was not
        names: list[str] = []
        while time.monotonic() < end and len(names) < SHARE - 10:  # the rest of the copy
            names = [n for n in _names(ws) if n.startswith("/loading:p")]
    # the copy came in slices, with the bystander's calls answered between them
    # (FETCH_SLICE: 25 slices of the first 2,500); one copy in one turn: no such answer
    assert late in names and len(names) >= SHARE - 10
    assert partial >= 1, (partial, calls)


def _names(ws: ClientConnection) -> list[str]:
    call = {"op": "call_service", "service": "/rosapi/get_param_names", "id": "names"}
    ws.send(json.dumps(call))
    while True:
        reply = json.loads(ws.recv(timeout=20))
        if reply.get("id") == "names":
            return list(reply["values"]["names"])
