"""The Python client (`rwt_client`) with a roslib (Node) peer via `rwt serve`.

The client calls services and sends goals that roslib provides (`Service.advertise`,
`advertiseAsync`, `Action.advertise`), then provides a service and an action that
roslib calls (`callService`, `sendGoal`, `cancelGoal`). The Python client runs in
this process (`SyncRos`, its loop on a background thread) as harness phases
between roslib's; roslib follows the drivers' reply and Fibonacci rules
(roslibpy_driver.py). The custom `rwt_test_interfaces/srv/Scale` goes both ways.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import anyio
import pytest

from rwt_client import Action, Ros, ServerGoal, Service, ServiceCallError, SyncRos

from .client_harness import (
    HARNESS,
    Phase,
    Running,
    ServerProcess,
    advertise_action,
    advertise_service,
    call,
    cancel_goal,
    connect,
    run_scenario,
    send_goal,
    sync,
    wait_calls,
    wait_feedback,
)

pytestmark = pytest.mark.node

ADD = "example_interfaces/srv/AddTwoInts"
TRIGGER = "std_srvs/srv/Trigger"
SCALE = "rwt_test_interfaces/srv/Scale"
FIBONACCI = "example_interfaces/action/Fibonacci"
GOALS = {"done": {"order": 5}, "cancel": {"order": 100}, "abort": {"order": -1}}
POINTS = [{"x": 1.5, "y": -2.0}, {"x": 0.0, "y": 4.0}]
HALF = {"points": [{"x": 0.75, "y": -1.0}, {"x": 0.0, "y": 2.0}], "note": "2 points"}
FIB5 = {"sequence": [0, 1, 1, 2, 3, 5]}
FEEDBACK5 = [{"sequence": FIB5["sequence"][:n]} for n in range(3, 7)]
WAIT_S = 10.0


async def call_roslib(ros: Ros) -> dict[str, Any]:
    """What the Python client gets from roslib's services and action."""
    seen: dict[str, Any] = {
        "add": await Service(ros, "/js/add", ADD).call({"a": 2, "b": 3}),
        "scale": await Service(ros, "/js/scale", SCALE).call({"points": POINTS, "factor": 0.5}),
    }
    with pytest.raises(ServiceCallError) as refused:
        await Service(ros, "/js/refuse", TRIGGER).call()
    seen["refuse"] = refused.value.values

    fibonacci = Action(ros, "/js/fibonacci", FIBONACCI)
    feedback: dict[str, list[object]] = {kind: [] for kind in GOALS}
    first_feedback = anyio.Event()

    def on_cancel_feedback(values: object) -> None:
        feedback["cancel"].append(values)
        first_feedback.set()

    handles = {
        "done": await fibonacci.send_goal(GOALS["done"], on_feedback=feedback["done"].append),
        "cancel": await fibonacci.send_goal(GOALS["cancel"], on_feedback=on_cancel_feedback),
        "abort": await fibonacci.send_goal(GOALS["abort"], on_feedback=feedback["abort"].append),
    }
    with anyio.fail_after(WAIT_S):
        await first_feedback.wait()
    await handles["cancel"].cancel()
    for kind, handle in handles.items():
        result = await handle.result(timeout_s=WAIT_S)
        seen[kind] = (result.result, result.status, result.values)
    seen["feedback"] = feedback
    return seen


async def fibonacci_server(goal: ServerGoal) -> dict[str, Any]:
    """The drivers' Fibonacci rules, as a Python client's action handler."""
    order = goal.args["order"]  # type: ignore[index]
    if order < 0:
        raise ValueError(f"order {order} is negative")  # ends the goal ABORTED
    sequence = [0, 1]
    if order >= 100:
        await goal.send_feedback({"sequence": sequence})
        with anyio.fail_after(WAIT_S):
            await goal.cancel_requested.wait()
        goal.canceled()
        return {"sequence": sequence}
    for _ in range(1, order):
        sequence.append(sequence[-1] + sequence[-2])
        await goal.send_feedback({"sequence": list(sequence)})
    return {"sequence": sequence}


def scale(request: dict[str, Any]) -> dict[str, Any]:
    factor = request["factor"]
    points = [{"x": p["x"] * factor, "y": p["y"] * factor} for p in request["points"]]
    return {"points": points, "note": f"{len(points)} points"}


async def provide(ros: Ros, served: list[object]) -> list[str]:
    """Offer services and an action to roslib; returns rosapi's service list after."""

    def add(request: dict[str, Any]) -> dict[str, Any]:
        served.append(request)
        return {"sum": request["a"] + request["b"]}

    async def refuse(request: object) -> object:
        raise ValueError("refused")  # roslib's failure callback gets the text

    def goal_handler(goal: ServerGoal) -> Any:
        served.append(goal.args)
        return fibonacci_server(goal)

    await Service(ros, "/py/add", ADD).advertise(add)
    await Service(ros, "/py/scale", SCALE).advertise(scale)
    await Service(ros, "/py/refuse", TRIGGER).advertise(refuse)
    await Action(ros, "/py/fibonacci", FIBONACCI).advertise(goal_handler)
    # Also the barrier: the server answers rosapi after it handled the advertisements.
    return await ros.get_services()


def roslib_calls_python() -> list[dict]:
    steps = [
        connect("jsc"),
        call("jsc", "add", "/py/add", ADD, {"a": 20, "b": 22}),
        call("jsc", "scale", "/py/scale", SCALE, {"points": POINTS, "factor": 0.5}),
        call("jsc", "refuse", "/py/refuse", TRIGGER),
    ]
    for kind, goal in GOALS.items():
        steps.append(send_goal("jsc", f"goal:{kind}", "/py/fibonacci", FIBONACCI, goal, wait=False))
    return [
        *steps,
        wait_feedback("goal:cancel", 1),
        cancel_goal("jsc", "goal:cancel"),
        wait_calls(*(f"goal:{kind}" for kind in GOALS)),
    ]


def test_python_client_and_roslib_serve_each_other(
    interfaces_server: ServerProcess, tmp_path: Path
) -> None:
    seen: dict[str, Any] = {}
    served: list[object] = []
    with SyncRos(interfaces_server.url) as client:

        def python_calls(running: Running) -> None:
            seen.update(client.run(call_roslib, client.ros))

        def python_provides(running: Running) -> None:
            seen["services"] = client.run(provide, client.ros, served)

        roslib_provides = [
            connect("jsp"),
            advertise_service("jsp", "/js/add", ADD, "add"),
            advertise_service("jsp", "/js/scale", "rwt_test_interfaces/Scale", "scale"),
            advertise_service("jsp", "/js/refuse", TRIGGER, "refuse"),
            advertise_action("jsp", "/js/fibonacci", FIBONACCI),
            sync("jsp"),
        ]
        phases: list[Phase] = [
            ("js", roslib_provides),
            (HARNESS, python_calls),
            (HARNESS, python_provides),
            ("js", roslib_calls_python()),
        ]
        outcome = run_scenario(interfaces_server.url, phases, {"js": "roslibjs"}, tmp_path)

    # The Python client calling roslib: values, the failure text, goal statuses (D18)
    assert seen["add"] == {"sum": 5}
    assert seen["scale"] == HALF
    assert seen["refuse"] == "Error: refused"  # what roslib's advertiseAsync sent
    assert seen["done"] == (True, 4, FIB5)
    assert seen["cancel"] == (True, 5, {"sequence": [0, 1]})  # roslib's setCanceled result
    assert seen["abort"] == (True, 6, {"sequence": []})  # setFailed sends no result
    assert seen["feedback"] == {"done": FEEDBACK5, "cancel": [{"sequence": [0, 1]}], "abort": []}
    assert outcome.served["jsp"]["/js/fibonacci"] == list(GOALS.values())
    assert {"/py/add", "/py/scale", "/py/refuse"} <= set(seen["services"])

    # roslib calling the Python client
    assert outcome.ok("add") == {"sum": 42}
    assert outcome.ok("scale") == HALF
    assert outcome.error("refuse") == "ValueError: refused"
    assert outcome.ok("goal:done") == FIB5
    assert outcome.feedback["goal:done"] == FEEDBACK5
    assert outcome.error("goal:cancel") == 'GoalError: Action was canceled: {"sequence":[0,1]}'
    assert outcome.feedback["goal:cancel"] == [{"sequence": [0, 1]}]
    assert outcome.error("goal:abort") == 'GoalError: Action was aborted: {"sequence":[]}'
    assert served == [{"a": 20, "b": 22}, *GOALS.values()]
