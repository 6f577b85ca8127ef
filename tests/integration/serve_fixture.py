"""A test server: `rwt serve` plus in-process services, an action server and an in-process caller.

Usage: python serve_fixture.py [--interfaces DIR]

Like `rwt serve --host 127.0.0.1 --port 0` (first stdout line `listening on
ws://HOST:PORT`), on a graph that also holds in-process providers whose replies
follow the same rules as the drivers' `advertise_service` replies (see
roslibpy_driver.py), so one table of expectations fits every provider:

    /inproc/set_bool  std_srvs/srv/SetBool         set_bool: {success: data, message: on|off}
    /inproc/trigger   std_srvs/srv/Trigger         trigger: {success: true, message: triggered}
    /inproc/empty     std_srvs/srv/Empty           empty: {}
    /inproc/add       example_interfaces/srv/AddTwoInts  add: {sum: a + b}
    /inproc/scale     rwt_test_interfaces/srv/Scale      scale (needs --interfaces)
    /inproc/refuse    std_srvs/srv/Trigger         refuse: raises, the caller gets the text
    /inproc/gather    example_interfaces/srv/AddTwoInts  add, answered only once GATHER
                      requests wait, then newest first
    /inproc/fibonacci example_interfaces/action/Fibonacci  the drivers' Fibonacci rules

The in-process caller is driven on stdin, one JSON object a line, and answers on
stdout, one JSON object a line, when the call or goal ends (calls run
concurrently, answers come in the order they end):

    {"op": "call", "as": NAME, "service": "/x", "args": {...}}
        -> {"as": NAME, "ok": response} or {"as": NAME, "error": text}
    {"op": "goal", "as": NAME, "action": "/x", "args": {...}}
        -> {"as": NAME, "ok": {"status": n, "values": result}, "feedback": [...]}
           or {"as": NAME, "error": text, "feedback": [...]}

They go through `rwt_graph.async_calls.call_service` and `send_action_goal`,
the API embedding code uses. Stops on SIGINT/SIGTERM or when stdin closes.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path

import anyio
import anyio.lowlevel
from anyio.abc import TaskGroup

from rwt_graph.actions import GoalCanceledError, GoalContext
from rwt_graph.async_calls import call_service, send_action_goal
from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.errors import RwtError
from rwt_transports.server import RosbridgeServer, ServerConfig

#: Requests /inproc/gather holds before it answers them, newest first.
GATHER = 12
#: Fibonacci goals: an order below 0 aborts, one from HOLD_ORDER on runs until canceled.
HOLD_ORDER = 100
CALL_TIMEOUT_S = 15.0

Message = dict[str, object]


def set_bool(request: Message) -> Message:
    return {"success": request["data"], "message": "on" if request["data"] else "off"}


def scale(request: Message) -> Message:
    factor = request["factor"]
    points = request["points"]
    assert isinstance(factor, float) and isinstance(points, list)
    scaled = [{"x": p["x"] * factor, "y": p["y"] * factor} for p in points]
    return {"points": scaled, "note": f"{len(scaled)} points"}


def refuse(request: Message) -> Message:
    raise RwtError("refused")  # a refusal with a reason (D4)


class Gather:
    """Holds AddTwoInts requests until GATHER wait, then answers the newest first.

    Each handler, once released, releases the one before it and returns; the
    graph sends its response before the next handler runs, so the answers leave
    in exactly the reverse order of arrival.
    """

    def __init__(self) -> None:
        self.gates: list[anyio.Event] = []

    async def __call__(self, request: Message) -> Message:
        index = len(self.gates)
        gate = anyio.Event()
        self.gates.append(gate)
        if len(self.gates) == GATHER:
            gate.set()
        await gate.wait()
        if index > 0:
            self.gates[index - 1].set()
        else:
            self.gates = []  # ready for the next batch
        a, b = request["a"], request["b"]
        assert isinstance(a, int) and isinstance(b, int)
        return {"sum": a + b}


async def fibonacci(goal: Message, context: GoalContext) -> Message:
    """The drivers' Fibonacci rules: feedback per term, abort below 0, hold from HOLD_ORDER."""
    order = goal["order"]
    assert isinstance(order, int)
    if order < 0:
        raise ValueError(f"order {order} is negative")
    sequence = [0, 1]
    if order >= HOLD_ORDER:
        context.publish_feedback({"sequence": sequence})
        # GoalContext offers a flag, not an event: look at it between steps, as a
        # real action server does.
        while not context.cancel_requested:
            await anyio.sleep(0.005)
        raise GoalCanceledError
    for _ in range(1, order):
        sequence.append(sequence[-1] + sequence[-2])
        context.publish_feedback({"sequence": list(sequence)})
        await anyio.lowlevel.checkpoint()
    return {"sequence": sequence}


def build_graph(interfaces: list[Path]) -> Graph:
    graph = Graph(TypeRegistry(Dialect.ROS2, interfaces))
    graph.create_service("/inproc/set_bool", "std_srvs/srv/SetBool", set_bool)
    graph.create_service(
        "/inproc/trigger",
        "std_srvs/srv/Trigger",
        lambda r: {"success": True, "message": "triggered"},
    )
    graph.create_service("/inproc/empty", "std_srvs/srv/Empty", lambda r: {})
    graph.create_service(
        "/inproc/add", "example_interfaces/srv/AddTwoInts", lambda r: {"sum": r["a"] + r["b"]}
    )
    graph.create_service("/inproc/refuse", "std_srvs/srv/Trigger", refuse)
    graph.create_service("/inproc/gather", "example_interfaces/srv/AddTwoInts", Gather())
    if interfaces:
        graph.create_service("/inproc/scale", "rwt_test_interfaces/srv/Scale", scale)
    graph.create_action_server(
        "/inproc/fibonacci", "example_interfaces/action/Fibonacci", fibonacci
    )
    return graph


def answer(reply: Message) -> None:
    print(json.dumps(reply), flush=True)


async def run_call(graph: Graph, command: Message) -> None:
    try:
        values = await call_service(
            graph, str(command["service"]), command.get("args"), timeout_s=CALL_TIMEOUT_S
        )
    except RwtError as exc:
        answer({"as": command["as"], "error": exc.message})
    else:
        answer({"as": command["as"], "ok": values})


async def run_goal(graph: Graph, command: Message) -> None:
    feedback: list[Message] = []
    try:
        outcome = await send_action_goal(
            graph,
            str(command["action"]),
            command.get("args"),
            on_feedback=feedback.append,
            timeout_s=CALL_TIMEOUT_S,
        )
    except RwtError as exc:
        answer({"as": command["as"], "error": exc.message, "feedback": feedback})
    else:
        ok = {"status": int(outcome.status), "values": outcome.result}
        answer({"as": command["as"], "ok": ok, "feedback": feedback})


async def read_commands(graph: Graph, tg: TaskGroup) -> None:
    runners = {"call": run_call, "goal": run_goal}
    while line := await anyio.to_thread.run_sync(sys.stdin.readline, abandon_on_cancel=True):
        command = json.loads(line)
        tg.start_soon(runners[command["op"]], graph, command)
    tg.cancel_scope.cancel()  # stdin closed: the test is done with us


async def main(interfaces: list[Path]) -> None:
    graph = build_graph(interfaces)
    server = RosbridgeServer(graph, ServerConfig(host="127.0.0.1", port=0))
    async with anyio.create_task_group() as tg:
        tg.start_soon(stop_on_signal, tg)
        url = await tg.start(server.serve)
        print(f"listening on {url}", flush=True)
        tg.start_soon(read_commands, graph, tg)


async def stop_on_signal(tg: TaskGroup) -> None:
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for _ in signals:
            tg.cancel_scope.cancel()
            return


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--interfaces", type=Path, action="append", default=[])
    anyio.run(main, parser.parse_args().interfaces)
