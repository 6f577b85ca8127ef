"""In-process services and actions, sync and async, called from Python and from sessions."""

from __future__ import annotations

import json

import anyio
import anyio.lowlevel
import pytest
from tests.conftest import Peer

from rwt_graph.actions import GoalCanceledError, GoalContext
from rwt_graph.async_calls import ServiceCallError, call_service, send_action_goal
from rwt_graph.graph import Graph
from rwt_protocol.ports import GoalStatus
from rwt_transports.server import running_handlers, spawner_for

pytestmark = pytest.mark.anyio

FIB = "example_interfaces/action/Fibonacci"


async def fibonacci(goal: dict[str, object], context: GoalContext) -> dict[str, object]:
    order = goal["order"]
    assert isinstance(order, int)
    sequence = [0, 1]
    for _ in range(1, order):
        if context.cancel_requested:
            raise GoalCanceledError
        sequence.append(sequence[-1] + sequence[-2])
        context.publish_feedback({"sequence": list(sequence)})
        await anyio.lowlevel.checkpoint()
    return {"sequence": sequence}


async def test_async_service_called_from_python_and_from_a_client() -> None:
    graph = Graph()

    async def add(request: dict[str, object]) -> dict[str, object]:
        await anyio.lowlevel.checkpoint()
        return {"sum": request["a"] + request["b"]}  # type: ignore[operator]

    graph.create_service("/add", "example_interfaces/srv/AddTwoInts", add)
    async with running_handlers(graph) as tg:
        with anyio.fail_after(5):
            assert await call_service(graph, "/add", {"a": 2, "b": 40}) == {"sum": 42}
            client = Peer(graph, "c")
            client.send(op="call_service", service="add", args=[1, 2], id="x")
            while not (frames := client.received()):
                await anyio.sleep(0.01)
        assert frames == [
            {
                "op": "service_response",
                "service": "add",
                "values": {"sum": 3},
                "result": True,
                "id": "x",
            }
        ]
        tg.cancel_scope.cancel()


async def test_async_service_without_a_loop_fails_cleanly() -> None:
    graph = Graph()

    async def never(request: dict[str, object]) -> dict[str, object]:
        return {}

    graph.create_service("/e", "std_srvs/srv/Empty", never)
    client = Peer(graph, "c")
    client.send(op="call_service", service="/e")
    [reply] = client.received()
    assert reply["result"] is False and "no event loop" in str(reply["values"])


async def test_python_caller_times_out_on_a_silent_provider() -> None:
    graph = Graph()
    provider = Peer(graph, "p")
    provider.send(op="advertise_service", service="/slow", type="std_srvs/Trigger")
    with anyio.fail_after(5), pytest.raises(ServiceCallError, match="timed out"):
        await call_service(graph, "/slow", timeout_s=0.05)
    assert provider.received()[0]["op"] == "call_service"


async def test_in_process_action_server_with_feedback_for_python_and_clients() -> None:
    graph = Graph()
    graph.create_action_server("/fib", FIB, fibonacci)
    feedback: list[dict[str, object]] = []
    async with running_handlers(graph) as tg:
        with anyio.fail_after(5):
            outcome = await send_action_goal(
                graph, "/fib", {"order": 5}, on_feedback=feedback.append
            )
        assert outcome.status is GoalStatus.SUCCEEDED
        assert outcome.result == {"sequence": [0, 1, 1, 2, 3, 5]}
        assert feedback[-1] == {"sequence": [0, 1, 1, 2, 3, 5]}
        assert len(feedback) == 4

        client = Peer(graph, "c")
        client.send(
            op="send_action_goal",
            action="/fib",
            action_type=FIB,
            args={"order": 3},
            feedback=True,
            id="g",
        )
        frames: list[dict[str, object]] = []
        with anyio.fail_after(5):
            while not frames or frames[-1]["op"] != "action_result":
                frames += client.received()
                await anyio.sleep(0.01)
        assert [f["op"] for f in frames] == ["action_feedback", "action_feedback", "action_result"]
        assert frames[-1]["values"] == {"sequence": [0, 1, 1, 2]} and frames[-1]["status"] == 4
        tg.cancel_scope.cancel()


async def test_the_goal_op_alone_says_whether_its_caller_gets_feedback() -> None:
    """A goal with ``feedback: false`` gets its result alone; ``true`` its feedback too."""
    graph = Graph()
    graph.create_action_server("/fib", FIB, fibonacci)
    quiet, chatty = Peer(graph, "quiet"), Peer(graph, "chatty")
    async with running_handlers(graph) as tg:
        for peer, wanted in ((quiet, False), (chatty, True)):
            peer.send(
                op="send_action_goal",
                action="/fib",
                action_type=FIB,
                args={"order": 3},
                feedback=wanted,
                id="g",
            )
        frames: dict[str, list[dict[str, object]]] = {"quiet": [], "chatty": []}
        with anyio.fail_after(5):
            while any(not got or got[-1]["op"] != "action_result" for got in frames.values()):
                frames["quiet"] += quiet.received()
                frames["chatty"] += chatty.received()
                await anyio.sleep(0.01)
        tg.cancel_scope.cancel()
    assert [f["op"] for f in frames["quiet"]] == ["action_result"]
    assert [f["values"] for f in frames["chatty"][:-1]] == [
        {"sequence": [0, 1, 1]},
        {"sequence": [0, 1, 1, 2]},
    ]
    assert frames["chatty"][-1]["status"] == frames["quiet"][-1]["status"] == 4


async def test_feedback_marked_validated_reaches_the_client_as_checked_feedback_does() -> None:
    graph = Graph()
    given = {"sequence": [0, 1, 1]}
    internal = graph.registry.action(FIB).feedback.from_json(given, now=0.0).msg

    async def twice(goal: dict[str, object], context: GoalContext) -> dict[str, object]:
        context.publish_feedback(given)
        context.publish_feedback(internal, validated=True)
        return {"sequence": []}

    graph.create_action_server("/twice", FIB, twice)
    async with running_handlers(graph) as tg:
        client = Peer(graph, "c")
        client.send(op="send_action_goal", action="/twice", action_type=FIB, feedback=True)
        frames: list[str | bytes] = []
        with anyio.fail_after(5):
            while len(frames) < 3:
                frames += [frame.data for frame in client.session.frames_to_send()]
                await anyio.wait_all_tasks_blocked()
        checked, trusted, result = frames
        assert trusted == checked
        assert json.loads(checked)["values"] == {"sequence": [0, 1, 1]}
        assert json.loads(result)["op"] == "action_result"
        tg.cancel_scope.cancel()


async def test_in_process_goal_cancelled_by_a_client() -> None:
    graph = Graph()
    started = anyio.Event()

    async def slow(goal: dict[str, object], context: GoalContext) -> dict[str, object]:
        started.set()
        while not context.cancel_requested:
            await anyio.sleep(0.01)
        raise GoalCanceledError

    graph.create_action_server("/slow", FIB, slow)
    async with running_handlers(graph) as tg:
        client = Peer(graph, "c")
        client.send(op="send_action_goal", action="/slow", action_type=FIB, id=7)
        with anyio.fail_after(5):
            await started.wait()
            client.send(op="cancel_action_goal", action="/slow", id=7)
            while not (frames := client.received()):
                await anyio.sleep(0.01)
        assert json.loads(json.dumps(frames[0]))["status"] == 5
        tg.cancel_scope.cancel()


async def test_failing_action_handler_aborts_the_goal() -> None:
    graph = Graph()

    async def broken(goal: dict[str, object], context: GoalContext) -> dict[str, object]:
        raise RuntimeError("motor fault")

    graph.create_action_server("/broken", FIB, broken)
    async with running_handlers(graph) as tg:
        with anyio.fail_after(5):
            outcome = await send_action_goal(graph, "/broken", {"order": 1})
        assert outcome.status is GoalStatus.ABORTED
        tg.cancel_scope.cancel()


async def test_python_caller_gets_a_provider_failure_as_service_call_error() -> None:
    graph = Graph()
    provider = Peer(graph, "p")
    provider.send(op="advertise_service", service="/fail", type="std_srvs/Trigger")

    async def refuse() -> None:
        while not (calls := provider.received()):
            await anyio.sleep(0.01)
        provider.send(
            op="service_response", service="/fail", id=calls[0]["id"], result=False, values="off"
        )

    async with anyio.create_task_group() as tg:
        tg.start_soon(refuse)
        with anyio.fail_after(5), pytest.raises(ServiceCallError, match="off"):
            await call_service(graph, "/fail")


async def test_python_goal_times_out_on_a_silent_action_server() -> None:
    graph = Graph()
    provider = Peer(graph, "p")
    provider.send(op="advertise_action", action="/quiet", type=FIB)
    with anyio.fail_after(5), pytest.raises(ServiceCallError, match="timed out"):
        await send_action_goal(graph, "/quiet", {"order": 1}, timeout_s=0.05)
    assert provider.received()[0]["op"] == "send_action_goal"


async def test_an_async_service_called_from_a_plain_loop_callback_answers() -> None:
    # links call the graph from event-loop callbacks another thread scheduled (a ROS 2
    # hand-over), where no task runs and no context says which async library runs:
    # the handler's job must still start
    import asyncio  # noqa: PLC0415
    import contextvars  # noqa: PLC0415

    graph = Graph()

    async def add(request: dict[str, object]) -> dict[str, object]:
        await anyio.lowlevel.checkpoint()
        return {"sum": request["a"] + request["b"]}  # type: ignore[operator]

    graph.create_service("/add", "example_interfaces/srv/AddTwoInts", add)
    replies: list[tuple[bool, object]] = []
    async with running_handlers(graph) as tg:
        asyncio.get_running_loop().call_soon(
            lambda: graph.port.call_service(
                "caller", "/add", {"a": 2, "b": 3}, lambda ok, values: replies.append((ok, values))
            ),
            context=contextvars.Context(),
        )
        with anyio.fail_after(5):
            while not replies:
                await anyio.sleep(0.01)
        tg.cancel_scope.cancel()
    assert replies == [(True, {"sum": 5})]


async def test_a_job_spawned_and_cancelled_in_one_plain_callback_never_runs() -> None:
    import asyncio  # noqa: PLC0415
    import contextvars  # noqa: PLC0415

    ran: list[str] = []

    async def job() -> None:
        ran.append("ran")

    async with anyio.create_task_group() as tg:
        spawn = spawner_for(tg)

        def spawn_and_cancel() -> None:
            cancel = spawn(job)
            cancel()

        loop = asyncio.get_running_loop()
        loop.call_soon(spawn_and_cancel, context=contextvars.Context())
        loop.call_soon(lambda: spawn(job) and None, context=contextvars.Context())
        with anyio.fail_after(5):
            while not ran:
                await anyio.sleep(0.01)
        await anyio.sleep(0.05)
    assert ran == ["ran"]


async def test_closing_an_async_service_fails_its_running_calls_and_cancels_them() -> None:
    # D15 for in-process providers: the service goes, its callers hear so at once
    graph = Graph()
    entered = anyio.Event()
    cancelled: list[bool] = []

    async def hold(request: dict[str, object]) -> dict[str, object]:
        entered.set()
        try:
            await anyio.sleep_forever()
        except anyio.get_cancelled_exc_class():
            cancelled.append(True)
            raise
        return {}

    service = graph.create_service("/hold", "std_srvs/srv/Trigger", hold)
    replies: list[tuple[bool, object]] = []
    async with running_handlers(graph) as tg:
        graph.port.call_service("c", "/hold", {}, lambda ok, values: replies.append((ok, values)))
        with anyio.fail_after(5):
            await entered.wait()
        service.close()
        with anyio.fail_after(5):
            while not cancelled:
                await anyio.sleep(0.01)
        tg.cancel_scope.cancel()
    assert replies == [(False, "service /hold was unadvertised")]


async def test_a_caller_that_stops_waiting_leaves_nothing_behind_in_the_service() -> None:
    graph = Graph()

    async def hold(request: dict[str, object]) -> dict[str, object]:
        await anyio.sleep_forever()
        return {}

    graph.create_service("/hold", "std_srvs/srv/Trigger", hold)
    async with running_handlers(graph) as tg:
        for _ in range(3):
            with pytest.raises(ServiceCallError, match="timed out"):
                await call_service(graph, "/hold", timeout_s=0.05)
        entry = graph.services.entries.get("/hold")
        assert entry is not None and not entry.running
        tg.cancel_scope.cancel()
