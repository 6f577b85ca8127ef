"""Actions with real clients: roslib (Node) and in-process servers, three kinds of client.

Action servers: roslib's ROS 2 `Action.advertise` (sendFeedback, setSucceeded,
setCanceled, setFailed) and an in-process `Graph.create_action_server` in
serve_fixture.py; both follow the drivers' Fibonacci rules (roslibpy_driver.py):
order 5 succeeds after four feedback messages, order 100 waits for a cancel,
order -1 aborts. Clients: roslib (`Action.sendGoal`, `cancelGoal`), roslibpy 2.x
(`ActionClient.send_goal`, `cancel_goal`) and in-process code
(`rwt_graph.async_calls.send_action_goal`, which has no cancel of its own: a
cancelled wait forgets the goal). roslibpy has no action server. A roslib
action server killed mid-goal aborts every waiting goal with the reason.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from .client_harness import (
    HARNESS,
    Phase,
    ServerProcess,
    advertise_action,
    cancel_goal,
    connect,
    inproc,
    inproc_goal,
    inproc_wait,
    kill,
    run_scenario,
    send_goal,
    sync,
    wait_calls,
    wait_feedback,
    wait_served,
)

PY, JS = "roslibpy", "roslibjs"
FIBONACCI = "example_interfaces/action/Fibonacci"
SERVERS = {"roslib": "/js/fibonacci", "inproc": "/inproc/fibonacci"}
GOALS = {"done": {"order": 5}, "cancel": {"order": 100}, "abort": {"order": -1}}

FIB5 = {"sequence": [0, 1, 1, 2, 3, 5]}
FEEDBACK5 = [{"sequence": [0, 1, 1, 2, 3, 5][:n]} for n in range(3, 7)]
#: The result a canceled goal ends with: roslib's server sends the sequence so
#: far (setCanceled); an in-process server that raises GoalCanceledError sends the default.
CANCELED = {"roslib": {"sequence": [0, 1]}, "inproc": {"sequence": []}}
#: Aborted goals carry the default result (setFailed sends none, D18).
ABORTED = {"sequence": []}


def client_steps(conn: str) -> list[dict]:
    """Every goal at once on one connection; cancel the held ones after their first feedback."""
    steps = [connect(conn)]
    names = []
    for server, action in SERVERS.items():
        for kind, goal in GOALS.items():
            name = f"{conn}:{server}:{kind}"
            steps.append(send_goal(conn, name, action, FIBONACCI, goal, wait=False))
            names.append(name)
    for server in SERVERS:
        steps += [
            wait_feedback(f"{conn}:{server}:cancel", 1),
            cancel_goal(conn, f"{conn}:{server}:cancel"),
        ]
    return [*steps, wait_calls(*names)]


@pytest.mark.node
def test_goals_feedback_cancel_and_abort_across_clients_and_servers(
    fixture_server: ServerProcess, tmp_path: Path
) -> None:
    """roslib and roslibpy send three goals to a roslib and an in-process action server;
    in-process code sends goals to the roslib server."""
    server_steps = [
        connect("srv"),
        advertise_action("srv", "/js/fibonacci", FIBONACCI),
        sync("srv"),
    ]
    phases: list[Phase] = [
        ("js", [*server_steps, *client_steps("jsc")]),
        ("py", client_steps("pyc")),
        (
            HARNESS,
            inproc(
                fixture_server,
                inproc_goal("inproc:roslib:done", "/js/fibonacci", GOALS["done"]),
                inproc_goal("inproc:roslib:abort", "/js/fibonacci", GOALS["abort"]),
            ),
        ),
        ("js", []),  # the roslib server stays until the in-process goals ended
    ]

    outcome = run_scenario(fixture_server.url, phases, {"js": JS, "py": PY}, tmp_path)

    for server, action in SERVERS.items():
        # roslib: the result callback gets the result; the failure callback a
        # GoalError text for the other terminal statuses (status 5 and 6 come
        # with result: true, D18).
        assert outcome.ok(f"jsc:{server}:done") == FIB5
        assert outcome.error(f"jsc:{server}:cancel") == (
            f"GoalError: Action was canceled: {_js_json(CANCELED[server])}"
        )
        assert outcome.error(f"jsc:{server}:abort") == (
            f"GoalError: Action was aborted: {_js_json(ABORTED)}"
        )
        # roslibpy: the result callback gets the status and the result every time
        assert outcome.ok(f"pyc:{server}:done") == {"status": 4, "values": FIB5}
        assert outcome.ok(f"pyc:{server}:cancel") == {"status": 5, "values": CANCELED[server]}
        assert outcome.ok(f"pyc:{server}:abort") == {"status": 6, "values": ABORTED}
        for conn in ("jsc", "pyc"):
            assert outcome.feedback[f"{conn}:{server}:done"] == FEEDBACK5
            assert outcome.feedback[f"{conn}:{server}:cancel"] == [{"sequence": [0, 1]}]
            assert outcome.feedback[f"{conn}:{server}:abort"] == []
            # the id sendGoal/send_goal returned, which the cancel used
            assert outcome.goal_ids[f"{conn}:{server}:cancel"].startswith(
                f"send_action_goal:{action}:"
            )
    assert outcome.ok("inproc:roslib:done") == {"status": 4, "values": FIB5}
    assert outcome.feedback["inproc:roslib:done"] == FEEDBACK5
    assert outcome.ok("inproc:roslib:abort") == {"status": 6, "values": ABORTED}
    # the goals as roslib's server callback got them: roslib's, roslibpy's, in-process
    assert outcome.served["srv"]["/js/fibonacci"] == [
        *GOALS.values(),
        *GOALS.values(),
        GOALS["done"],
        GOALS["abort"],
    ]


@pytest.mark.node
def test_action_server_killed_mid_goal_aborts_the_waiting_goals(
    fixture_server: ServerProcess, tmp_path: Path
) -> None:
    """SIGKILL a roslib action server while goals of roslib, roslibpy and in-process code
    wait: each ends ABORTED with the reason (D4)."""
    hold = GOALS["cancel"]  # waits for a cancel that never comes
    action = "/js/fibonacci"

    def goal(conn: str) -> dict:
        return send_goal(conn, conn, action, FIBONACCI, hold, wait=False)

    phases: list[Phase] = [
        ("server", [connect("srv"), advertise_action("srv", action, FIBONACCI), sync("srv")]),
        ("js", [connect("jsc"), goal("jsc")]),
        ("py", [connect("pyc"), goal("pyc")]),
        (HARNESS, inproc(fixture_server, inproc_goal("inproc", action, hold), wait=False)),
        ("server", [wait_served("srv", action, 3)]),
        (HARNESS, kill("server")),
        ("js", [wait_calls("jsc")]),
        ("py", [wait_calls("pyc")]),
        (HARNESS, inproc_wait(fixture_server, "inproc")),
    ]

    outcome = run_scenario(fixture_server.url, phases, {"server": JS, "js": JS, "py": PY}, tmp_path)

    reason = "action /js/fibonacci is gone: its provider disconnected"
    assert outcome.error("jsc") == f"GoalError: Action was aborted: {reason}"
    assert outcome.error("pyc") == {"status": 6, "values": reason}  # roslibpy's errback
    assert outcome.error("inproc") == reason  # ServiceCallError
    assert outcome.feedback["jsc"] == outcome.feedback["pyc"] == [{"sequence": [0, 1]}]


def _js_json(value: object) -> str:
    """JSON.stringify's spelling (no spaces)."""
    return json.dumps(value, separators=(",", ":"))
