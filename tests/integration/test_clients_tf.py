"""Real TF clients against the built-in tf2_web_republisher (paper IV.A, REF §7.3).

The server is examples/tf_robot.py: an in-process TF publisher moves ``arm`` 1 cm
and turns ``wrist`` 0.02 rad every 50 ms; ``camera`` is static. Each client
library's TF client subscribes to the three frames in ``base_link`` with 4.5 cm /
0.09 rad thresholds, next to an "eager" client whose zero translation threshold
asks for every tick. What their callbacks got shows the thresholds at work:
successive values of a thresholded client differ by more than a threshold, the
static frame comes once, and the eager client sees the small steps the others skip.
"""

from __future__ import annotations

import itertools
import json
import math
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from websockets.sync.client import connect as connect_ws

from .client_harness import (
    REPO,
    Outcome,
    ServerProcess,
    connect,
    quiet,
    run_scenario,
    tf_client,
    tf_dispose,
    tf_wait,
)

FRAMES = ["arm", "wrist", "camera"]
#: Not multiples of the robot's steps (1 cm, 0.02 rad), so no move ties a threshold.
TRANS, ANGLE = 0.045, 0.09


@pytest.fixture(scope="module", params=["ros2", "ros1"])
def shared_tf_robot(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[ServerProcess]:
    """One robot of each dialect for the module: each test's TF clients are its own
    (their own connection, subscriptions and thresholds) and disposed at its end."""
    script = str(REPO / "examples" / "tf_robot.py")
    workdir = tmp_path_factory.mktemp(f"tf_robot_{request.param}")
    server = ServerProcess(workdir, cmd=[sys.executable, script, "0", request.param])
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def tf_robot(request: pytest.FixtureRequest, shared_tf_robot: ServerProcess) -> ServerProcess:
    """The shared robot, its stderr attached to a failing test's report (conftest.py)."""
    request.node._rwt_server = shared_tf_robot
    return shared_tf_robot


def distance(a: dict, b: dict) -> float:
    return math.dist(*([t["translation"][k] for k in "xyz"] for t in (a, b)))


def angle(a: dict, b: dict) -> float:
    dot = abs(sum(a["rotation"][k] * b["rotation"][k] for k in "xyzw"))
    return 2 * math.acos(min(1.0, dot))


def steps_of(transforms: list[dict]) -> list[tuple[float, float]]:
    """(distance, angle) between successive transforms a callback got."""
    return [(distance(a, b), angle(a, b)) for a, b in itertools.pairwise(transforms)]


def check_thresholds(outcome: Outcome, name: str) -> None:
    got = outcome.tf[name]
    assert len(got["camera"]) == 1, "a static frame is sent once"
    assert got["camera"][0]["translation"] == {"x": 0.2, "y": 0.0, "z": 0.0}
    for frame in ("arm", "wrist"):
        steps = steps_of(got[frame])
        assert len(steps) >= 3, (frame, got[frame])
        assert all(moved > TRANS or turned > ANGLE for moved, turned in steps), (name, frame, steps)
    assert all(moved > TRANS for moved, _ in steps_of(got["arm"])), "arm only slides"


def check_eager(outcome: Outcome, name: str) -> None:
    steps = steps_of(outcome.tf[name]["arm"])
    assert any(moved < TRANS for moved, _ in steps), ("every tick is sent", steps)


def scenario(*clients: str) -> list[dict]:
    steps = [connect("web")]
    for client in clients:
        name = client.lower()
        steps.append(tf_client("web", name, client, FRAMES, angular_thres=ANGLE, trans_thres=TRANS))
    eager = clients[0]
    steps.append(tf_client("web", "eager", eager, ["arm"], trans_thres=0.0, rate=20.0))
    for client in clients:
        steps += [tf_wait(client.lower(), "arm", 4), tf_wait(client.lower(), "wrist", 4)]
    steps += [tf_wait("eager", "arm", 6), quiet(200)]
    return steps + [tf_dispose(client.lower()) for client in (*clients, "eager")]


def test_roslibpy_tf_client(tf_robot: ServerProcess, tmp_path: Path) -> None:
    outcome = run_scenario(
        tf_robot.url, [("web", scenario("TFClient"))], {"web": "roslibpy"}, tmp_path
    )
    check_thresholds(outcome, "tfclient")
    check_eager(outcome, "eager")


@pytest.mark.node
def test_roslib_tf_clients(tf_robot: ServerProcess, tmp_path: Path) -> None:
    """ROS2TFClient (the action), TFClient (actionlib topics, as ros3djs uses it) and
    TFClient fed from /republish_tfs through processResponse."""
    clients = ("ROS2TFClient", "TFClient", "TFClient+service")
    outcome = run_scenario(
        tf_robot.url, [("web", scenario(*clients))], {"web": "roslibjs"}, tmp_path
    )
    for client in clients:
        check_thresholds(outcome, client.lower())
    check_eager(outcome, "eager")
    assert outcome.statuses == []  # nothing the server refused


def test_rwt_serve_no_tf_offers_none_of_it(tmp_path: Path) -> None:
    server = ServerProcess(tmp_path, extra_args=("--no-tf",))
    try:
        with connect_ws(server.url) as ws:
            ws.send(json.dumps({"op": "call_service", "service": "/rosapi/nodes", "id": "n"}))
            nodes = json.loads(ws.recv(timeout=10))
            assert "/tf2_web_republisher" not in nodes["values"]["nodes"]
            ws.send(json.dumps({"op": "call_service", "service": "/republish_tfs", "id": "r"}))
            refused = json.loads(ws.recv(timeout=10))
            assert refused["result"] is False and "does not exist" in refused["values"]
    finally:
        server.stop()
