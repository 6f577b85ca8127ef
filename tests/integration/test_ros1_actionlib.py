"""roslibpy's ROS 1 ActionClient and SimpleActionServer through `rwt serve --dialect ros1`.

ROS 1 actions travel over five topics typed with the messages genaction makes of
the `.action` file (`actionlib_tutorials/FibonacciActionGoal`...). rwt makes
them too, for the shipped actionlib_tutorials and for a user's own `.action` file
given with `--interfaces`; here a roslibpy client runs a goal to its result
against a roslibpy server, each on its own connection.
"""

from __future__ import annotations

import os
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import roslibpy
from roslibpy.ros1.actionlib import ActionClient, Goal, SimpleActionServer

from tests.support.cli import RWT

SRC = str(Path(__file__).resolve().parents[2] / "src")
TIMEOUT_S = 15


@pytest.fixture
def interfaces(tmp_path: Path) -> Path:
    """A user's own action, as `--interfaces DIR` gives it."""
    folder = tmp_path / "my_actions" / "action"
    folder.mkdir(parents=True)
    (folder / "Countdown.action").write_text("int32 start\n---\nstring done\n---\nint32 left\n")
    return tmp_path


@pytest.fixture
def ros1_server(interfaces: Path) -> Iterator[int]:
    """`rwt serve --dialect ros1 --interfaces DIR` on a free port; yields the port."""
    command = [*RWT, "serve", "--host", "127.0.0.1"]
    command += ["--port", "0", "--dialect", "ros1", "--interfaces", str(interfaces)]
    process = subprocess.Popen(
        command,
        env={**os.environ, "PYTHONPATH": SRC},
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        assert line.startswith("listening on ws://"), line
        yield int(line.strip().rsplit(":", 1)[1])
    finally:
        process.terminate()
        process.wait(timeout=10)
        if process.stdout is not None:
            process.stdout.close()


def _connect(port: int) -> roslibpy.Ros:
    ros = roslibpy.Ros(host="127.0.0.1", port=port)
    ros.run(timeout=TIMEOUT_S)
    return ros


def _serve(ros: roslibpy.Ros, name: str, action_type: str, step: str, count: str) -> None:
    """A roslibpy action server: feedback for each step, then the result."""
    server = SimpleActionServer(ros, name, action_type)

    def execute(goal: dict[str, object]) -> None:
        n = int(goal[count])  # type: ignore[call-overload]
        if step == "sequence":  # Fibonacci: the sequence so far, then all of it
            sequence = [0, 1]
            for _ in range(1, n):
                sequence.append(sequence[-1] + sequence[-2])
                server.send_feedback({"sequence": sequence})
            server.set_succeeded({"sequence": sequence})
        else:  # Countdown: what is left, then done
            for left in range(n - 1, -1, -1):
                server.send_feedback({"left": left})
            server.set_succeeded({"done": "liftoff"})

    server.start(execute)


def _run_goal(
    ros: roslibpy.Ros, name: str, action_type: str, goal: dict[str, object]
) -> tuple[object, list[dict[str, object]]]:
    client = ActionClient(ros, name, action_type)
    feedback: list[dict[str, object]] = []
    got_feedback = threading.Event()

    def on_feedback(message: dict[str, object]) -> None:
        feedback.append(message)
        got_feedback.set()

    sent = Goal(client, roslibpy.Message(goal))
    sent.on("feedback", on_feedback)
    sent.send()
    result = sent.wait(TIMEOUT_S)
    client.dispose()
    return result, feedback


@pytest.mark.parametrize(
    ("action_type", "goal", "step", "count", "expected"),
    [
        (
            "actionlib_tutorials/FibonacciAction",
            {"order": 5},
            "sequence",
            "order",
            {"sequence": [0, 1, 1, 2, 3, 5]},
        ),
        ("my_actions/CountdownAction", {"start": 3}, "left", "start", {"done": "liftoff"}),
    ],
    ids=["shipped-fibonacci", "user-action"],
)
def test_a_ros1_action_goal_runs_to_its_result(
    ros1_server: int,
    action_type: str,
    goal: dict[str, object],
    step: str,
    count: str,
    expected: dict[str, object],
) -> None:
    server_ros, client_ros = _connect(ros1_server), _connect(ros1_server)
    try:
        _serve(server_ros, "/act", action_type, step, count)
        result, feedback = _run_goal(client_ros, "/act", action_type, goal)
        assert result == expected
        assert feedback  # at least one feedback message arrived, typed by genaction
    finally:
        client_ros.close()
        server_ros.close()
