"""Both MCP revisions from one endpoint, and goals as tasks, with the official SDK's client.

The SDK's client (2.x) speaks the 2026-07-28 revision (no handshake, ``_meta`` on
every request, ``server/discover``, ``subscriptions/listen``, the Tasks extension)
or, with ``mode="legacy"``, a 2025-era client's (``initialize``, a session,
``resources/subscribe``). Each drives ``rwt serve --mcp`` (in-process) and ``rwt
mcp URL`` (a process the client starts): tools, resources, updates and a goal.
A goal started as a task is polled and canceled from another connection, and
the robot's action server sees the cancel (docs/mcp.md, "Goals as tasks"; D35, D52).
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from typing import Any, Literal

import anyio
import pytest

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_graph.actions import GoalCanceledError, GoalContext

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp import Client, StdioServerParameters
from mcp.client.extension import ClaimContext, ClientExtension, ResultClaim
from mcp.server.mcpserver.exceptions import ToolError
from mcp.shared.exceptions import MCPError
from mcp.types import CallToolResult, Request, RequestParams, Result, TextContent
from pydantic import ConfigDict

from rwt_mcp.link import Goal
from rwt_mcp.tasks import MAX_TASKS, TASK_TTL_S, TASKS_EXTENSION, TaskStore
from rwt_transports.admission.shares import HostShares
from rwt_transports.http.mcp_options import McpOptions
from tests.support.cli import ENV, RWT

pytestmark = pytest.mark.anyio

FIB = "example_interfaces/action/Fibonacci"
HOLD_ORDER = 100  # a goal of this order runs until canceled
MODERN = "2026-07-28"
AUTO = "auto"  # server/discover first, then 2026-07-28 where the server speaks it

Message = dict[str, Any]


class TaskHandle(Result):
    """A task handle (``resultType: "task"``), the extension's ``CreateTaskResult``."""

    model_config = ConfigDict(extra="allow", populate_by_name=True)
    result_type: Literal["task"] = "task"
    task_id: str
    status: str


class TaskState(Result):
    """``tasks/get``'s answer: the task's fields, inlined."""

    model_config = ConfigDict(extra="allow", populate_by_name=True)
    task_id: str
    status: str
    status_message: str | None = None


class _TaskIdParams(RequestParams):
    task_id: str


class Tasks(ClientExtension):
    """The Tasks extension of a client: declares it; a task handle is kept as it is."""

    identifier = TASKS_EXTENSION

    def claims(self) -> list[ResultClaim[Any]]:
        return [ResultClaim(result_type="task", model=TaskHandle, resolve=_unresolved)]


async def _unresolved(handle: TaskHandle, _ctx: ClaimContext) -> CallToolResult:
    return CallToolResult(content=[TextContent(type="text", text=handle.task_id)])


async def task_request(client: Client, method: str, task_id: str) -> TaskState | Result:
    """``tasks/get`` or ``tasks/cancel`` for ``task_id``, through the client's session."""
    request = Request[_TaskIdParams, str](method=method, params=_TaskIdParams(task_id=task_id))
    answer = TaskState if method == "tasks/get" else Result
    return await client.session.send_request(request, answer)


def robot(canceled: list[str], started: list[str] | None = None) -> Graph:
    """A battery topic, a counter, and ``/fibonacci``, whose long goals run until canceled.

    ``started``: each goal's id as the action server gets it.
    """
    graph = Graph()
    battery = graph.create_publisher("/battery", "std_msgs/msg/String", latch=True)
    battery.publish({"data": "87%"})

    async def fibonacci(goal: Message, context: GoalContext) -> Message:
        if started is not None:
            started.append(context.goal_id)
        sequence = [0, 1]
        if goal["order"] >= HOLD_ORDER:
            context.publish_feedback({"sequence": sequence})
            while not context.cancel_requested:
                await anyio.sleep(0.01)
            canceled.append(context.goal_id)
            raise GoalCanceledError
        for _ in range(1, goal["order"]):
            sequence.append(sequence[-1] + sequence[-2])
            context.publish_feedback({"sequence": sequence})
        return {"sequence": sequence}

    graph.create_action_server("/fibonacci", FIB, fibonacci)
    return graph


@pytest.fixture
async def served() -> AsyncIterator[tuple[str, Graph, list[str]]]:
    """rwt serving ``robot`` with ``--mcp``, in-process: ``(ws url, graph, goals canceled)``."""
    canceled: list[str] = []
    graph = robot(canceled)
    server = RosbridgeServer(graph, ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions()))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield url, graph, canceled
        tg.cancel_scope.cancel()


@asynccontextmanager
async def connect(url: str, front: str, mode: str, on_message: Any = None) -> AsyncIterator[Client]:
    """An SDK client of ``mode`` (``legacy``, or ``auto``: discover) on ``/mcp`` or stdio."""
    target: str | StdioServerParameters = "http://" + url.split("://", 1)[1] + "/mcp"
    if front == "stdio":
        args = [*RWT[1:], "mcp", url]  # forked by this worker's warm rwt
        target = StdioServerParameters(command=RWT[0], args=args, env=dict(ENV))
    extensions = [Tasks()]
    async with Client(
        target, mode=mode, extensions=extensions, message_handler=on_message
    ) as client:
        yield client


async def _goal_task(client: Client, order: int) -> str:
    arguments = {"action": "/fibonacci", "type": FIB, "goal": {"order": order}}
    handle = await client.session.call_tool("send_action_goal", arguments, allow_claimed=True)
    assert isinstance(handle, TaskHandle), handle
    assert handle.status == "working"
    return handle.task_id


async def _settled(client: Client, task_id: str, every_s: float = 0.05) -> TaskState:
    """The task once it ended, polled every ``every_s``."""
    while True:
        state = await task_request(client, "tasks/get", task_id)
        assert isinstance(state, TaskState)
        if state.status != "working":
            return state
        await anyio.sleep(every_s)


@pytest.mark.parametrize("front", ["http", "stdio"])
async def test_a_2026_client_lists_reads_listens_and_drives_a_task(
    served: tuple[str, Graph, list[str]], front: str
) -> None:
    url, graph, _ = served
    counter = graph.create_publisher("/counter", "std_msgs/msg/Int32")
    with anyio.fail_after(60):
        async with connect(url, front, AUTO) as client:
            assert client.protocol_version == MODERN  # no initialize: _meta on each request
            assert TASKS_EXTENSION in (client.server_capabilities.extensions or {})
            assert len((await client.list_tools()).tools) == 17
            echoed = await client.call_tool("echo", {"topic": "/battery"})
            assert json.loads(echoed.content[1].text) == {"data": "87%"}  # type: ignore[union-attr]
            listed = await client.list_resources()
            assert "ros://topics/battery" in {str(r.uri) for r in listed.resources}
            read = await client.read_resource("ros://topics/battery")
            assert json.loads(read.contents[0].text) == {"data": "87%"}  # type: ignore[union-attr]

            async with client.listen(resource_subscriptions=["ros://topics/counter"]) as events:
                counter.publish({"data": 7})
                event = await events.__anext__()
                assert getattr(event, "uri", None) == "ros://topics/counter"
                latest = await client.read_resource("ros://topics/counter")
                assert json.loads(latest.contents[0].text) == {"data": 7}  # type: ignore[union-attr]

            state = await _settled(client, await _goal_task(client, 5))
            assert state.status == "completed"
            report = state.model_extra["result"]["structuredContent"]  # type: ignore[index]
            assert report["state"] == "succeeded"
            assert report["result"] == {"sequence": [0, 1, 1, 2, 3, 5]}


@pytest.mark.parametrize("front", ["http", "stdio"])
async def test_a_2025_client_still_opens_a_session_and_subscribes(
    served: tuple[str, Graph, list[str]], front: str
) -> None:
    url, graph, _ = served
    counter = graph.create_publisher("/counter", "std_msgs/msg/Int32")
    updated = anyio.Event()

    async def on_message(message: Any) -> None:
        if getattr(message, "method", None) == "notifications/resources/updated":
            updated.set()

    with anyio.fail_after(60):
        async with connect(url, front, "legacy", on_message) as client:
            assert client.protocol_version == "2025-11-25"  # the initialize handshake
            assert len((await client.list_tools()).tools) == 17
            await client.subscribe_resource("ros://topics/counter")
            counter.publish({"data": 3})
            await updated.wait()
            latest = await client.read_resource("ros://topics/counter")
            assert json.loads(latest.contents[0].text) == {"data": 3}  # type: ignore[union-attr]
            arguments = {"action": "/fibonacci", "type": FIB, "goal": {"order": 3}}
            result = await client.call_tool("send_action_goal", arguments)  # no task: a result
            assert result.structured_content is not None
            assert result.structured_content["state"] == "succeeded"


@pytest.mark.parametrize("mode", ["legacy", AUTO], ids=["2025-era", "2026-07-28"])
async def test_a_call_nobody_answers_ends_on_the_sessions_timers(
    served: tuple[str, Graph, list[str]], mode: str
) -> None:
    """A service call's deadline is the session's call book's, on the runtime's timers.

    A 2025-era session's pump runs them; a 2026-07-28 request's session, which has no
    pump, has them driven for it (docs/architecture.md, "How to add").
    """
    url, graph, _ = served

    async def never(request: Message) -> Message:
        await anyio.sleep_forever()
        return {}

    graph.create_service("/hang", "std_srvs/srv/Trigger", never)
    with anyio.fail_after(60):
        async with connect(url, "http", mode) as client:
            late = await client.call_tool("call_service", {"service": "/hang", "timeout_s": 0.5})
            assert late.is_error
            text = late.content[0].text  # type: ignore[union-attr]
            assert "no service_response for /hang within 0.5 s" in text
            echoed = await client.call_tool("echo", {"topic": "/battery"})  # it goes on
            assert json.loads(echoed.content[1].text) == {"data": "87%"}  # type: ignore[union-attr]


@pytest.mark.parametrize("mode", ["legacy", AUTO], ids=["2025-era", "2026-07-28"])
async def test_a_topics_latest_message_comes_after_its_throttle(
    served: tuple[str, Graph, list[str]], mode: str
) -> None:
    """A resource's updates are throttled on the session's timers: the latest one comes.

    Two messages within ``resources.UPDATE_INTERVAL_S`` of the first: the newest is
    held and sent when the interval ends, whichever revision holds the subscription.
    """
    url, graph, _ = served
    counter = graph.create_publisher("/counter", "std_msgs/msg/Int32")
    updates = anyio.Event()

    async def on_message(message: Any) -> None:
        if getattr(message, "method", None) == "notifications/resources/updated":
            updates.set()

    async def latest(client: Client) -> int:
        read = await client.read_resource("ros://topics/counter")
        return int(json.loads(read.contents[0].text)["data"])  # type: ignore[union-attr]

    with anyio.fail_after(60):
        async with connect(url, "http", mode, on_message) as client:
            if mode == "legacy":
                await client.subscribe_resource("ros://topics/counter")
                counter.publish({"data": 1})
                await updates.wait()
                updates = anyio.Event()
                counter.publish({"data": 2})
                counter.publish({"data": 3})
                await updates.wait()  # the held one, when the interval ended
                assert await latest(client) == 3
                return
            async with client.listen(resource_subscriptions=["ros://topics/counter"]) as events:
                counter.publish({"data": 1})
                await events.__anext__()
                counter.publish({"data": 2})
                counter.publish({"data": 3})
                await events.__anext__()  # the held one, when the interval ended
                assert await latest(client) == 3


async def test_a_task_is_polled_and_canceled_from_a_new_connection(
    served: tuple[str, Graph, list[str]],
) -> None:
    url, _, canceled = served
    with anyio.fail_after(60):
        async with connect(url, "http", AUTO) as first:
            task_id = await _goal_task(first, HOLD_ORDER)
            state = await task_request(first, "tasks/get", task_id)
            assert isinstance(state, TaskState) and state.status == "working"
        # the agent reconnects: the task, and its goal, are the endpoint's
        async with connect(url, "http", AUTO) as second:
            state = await task_request(second, "tasks/get", task_id)
            assert isinstance(state, TaskState) and state.status == "working"
            goal_id = json.loads(state.status_message or "{}")["goal_id"]
            assert goal_id.startswith("send_action_goal:/fibonacci:")
            await task_request(second, "tasks/cancel", task_id)
            ended = await _settled(second, task_id)
            assert ended.status == "cancelled"
            assert json.loads(ended.status_message or "{}")["goal_id"] == goal_id
        assert len(canceled) == 1  # the robot's action server saw the cancel


async def test_a_cancel_ends_its_own_task_where_two_goals_share_an_id(
    served: tuple[str, Graph, list[str]],
) -> None:
    """Two tasks' goals, sent by two requests: a cancel ends its own goal alone."""
    url, _, canceled = served
    with anyio.fail_after(60):
        async with connect(url, "http", AUTO) as client:
            first = await _goal_task(client, HOLD_ORDER)
            second = await _goal_task(client, HOLD_ORDER)
            ids = set()
            for task_id in (first, second):
                state = await task_request(client, "tasks/get", task_id)
                assert isinstance(state, TaskState)
                ids.add(json.loads(state.status_message or "{}")["goal_id"])
            assert len(ids) == 2  # ids unique on the server: a cancel names one goal (D35)
            await task_request(client, "tasks/cancel", first)
            assert (await _settled(client, first)).status == "cancelled"
            state = await task_request(client, "tasks/get", second)
            assert isinstance(state, TaskState) and state.status == "working"
            await task_request(client, "tasks/cancel", second)
            assert (await _settled(client, second)).status == "cancelled"
        assert len(canceled) == 2


async def test_an_unknown_task_is_an_error(served: tuple[str, Graph, list[str]]) -> None:
    url, _, _ = served
    async with connect(url, "http", AUTO) as client:
        with pytest.raises(Exception, match="no task 'nope'"):
            await task_request(client, "tasks/get", "nope")


class _Handle:
    def __init__(self, goal_id: str) -> None:
        self.id = goal_id


class _Link:
    """A link whose robot takes cancels (the expiry's, sent from its task group), counting them."""

    def __init__(self) -> None:
        self.canceled: list[str] = []
        self.spawned: list[Callable[[], Awaitable[None]]] = []
        self.robot = self

    def spawn(self, function: Callable[[], Awaitable[None]]) -> None:
        self.spawned.append(function)

    async def cancel(self, record: Goal) -> None:
        self.canceled.append(record.handle.id)


def _started(store: TaskStore, link: _Link, name: str, host: str = "") -> tuple[Goal, Any]:
    """A goal ``name`` started as a task of ``store`` for ``host``: reserved, then added."""

    def report(record: Goal) -> Message:
        return {"state": "succeeded" if record.done.is_set() else "running"}

    store.reserve(host)
    goal = Goal("/fibonacci", _Handle(name))  # type: ignore[arg-type]
    return goal, store.add(goal, link, report, host)  # type: ignore[arg-type]


async def test_a_store_runs_max_tasks_and_forgets_them_after_their_ttl() -> None:
    now = [0.0]
    store = TaskStore(clock=lambda: now[0])  # one client (rwt mcp): no host share
    link = _Link()
    started = [_started(store, link, f"g{n}") for n in range(MAX_TASKS)]
    with pytest.raises(ToolError, match=f"{MAX_TASKS} tasks are running \\(MAX_TASKS\\)"):
        store.reserve("")
    started[0][0].done.set()  # a finished task makes room: its slot, and the oldest finished
    _started(store, link, "next")
    with pytest.raises(MCPError, match="unknown, or expired"):
        store.get(started[0][1].task_id)
    assert store.get(started[1][1].task_id).wire()["status"] == "working"
    now[0] = TASK_TTL_S  # every task's life is over: forgotten, running goals canceled
    with pytest.raises(MCPError, match="unknown, or expired"):
        store.get(started[1][1].task_id)
    for send in link.spawned:
        await send()
    assert len(link.canceled) == MAX_TASKS and not store.tasks and store.running == 0


def test_a_host_holds_its_share_of_the_running_tasks() -> None:
    store = TaskStore(clock=lambda: 0.0, shares=HostShares(MAX_TASKS))
    link = _Link()
    hog = [_started(store, link, f"a{n}", "a") for n in range(MAX_TASKS * 3 // 4)]
    with pytest.raises(ToolError, match="this host's 48 running tasks are its share of the 64"):
        store.reserve("a")
    assert [_started(store, link, f"b{n}", "b") for n in range(8)]  # half of the 16 free
    with pytest.raises(ToolError, match="this host's 8 running tasks"):
        store.reserve("b")
    hosts = ["c"] * 4 + ["d"] * 2 + ["e", "f"]  # each half of what is free, the last to one
    for n, host in enumerate(hosts):
        _started(store, link, f"{host}{n}", host)
    with pytest.raises(ToolError, match=f"{MAX_TASKS} tasks are running \\(MAX_TASKS\\)"):
        store.reserve("g")
    hog[0][0].done.set()  # an ended goal frees its slot: the last goes to a host holding none
    with pytest.raises(ToolError, match="this host's 47 running tasks"):
        store.reserve("a")
    store.reserve("g")
    store.unreserve("g")  # its goal was refused after: the slot is back
    store.reserve("h")
