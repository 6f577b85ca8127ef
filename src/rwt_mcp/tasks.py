"""Goals as MCP tasks: the Tasks extension (``io.modelcontextprotocol/tasks``).

A 2026-07-28 client that declares the extension in its request's capabilities
gets ``send_action_goal`` answered with a task handle (``resultType: "task"``)
instead of a result it would wait for (docs/mcp.md, "Goals as tasks"). The task
follows the goal: ``tasks/get`` answers its state (``working`` with the goal's
report, feedback count and last feedback as ``statusMessage``; ``completed`` with
the tool's result; ``cancelled``; ``failed`` when the connection that holds the
goal dropped), and ``tasks/cancel`` cancels the goal through the connection that
asks, as any connection the access rules allow on the action may (D35). The tasks
live in a ``TaskStore`` the front end shares between its sessions and requests
(one per ``rwt serve --mcp`` endpoint, one per ``rwt mcp`` process), so a task
started on one connection is polled and canceled from another.

Bounds (docs/limits.md, "MCP front end"): at most ``MAX_TASKS`` goals of a
store run at once, and a host's share of them is bound as the connection slots'
(the endpoint's ``HostShares``, D60): a task past either is a tool error, given
before its goal is sent (``TaskStore.reserve``). A store holds at most
``MAX_TASKS`` tasks (a new one drops the oldest finished one), and a task lives
``TASK_TTL_S`` from its creation (``ttlMs``): then it is forgotten, and a goal
still running is canceled. The wire shapes are the extension's 2026-07-28 schema
(``Task``, ``CreateTaskResult``, ``GetTaskResult``); ``tasks/cancel`` acknowledges
with the task as it stands (a goal that ended first: its end, D60), and
``tasks/update`` answers an error, since a goal asks for no input.
"""

from __future__ import annotations

import contextlib
import functools
import json
import uuid
from collections import OrderedDict
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any, Protocol

import anyio
from mcp.server.extension import Extension, MethodBinding
from mcp.server.mcpserver.exceptions import ToolError
from mcp.shared.exceptions import MCPError
from mcp.types import INVALID_PARAMS, CallToolRequestParams, CallToolResult, TextContent
from mcp.types.version import MODERN_PROTOCOL_VERSIONS
from mcp_types import RequestParams
from pydantic import Field, ValidationError

from rwt_protocol.errors import GraphError, RwtError
from rwt_protocol.runtime.access import log_refused

from .catalog import TASK_TOOLS

if TYPE_CHECKING:
    from collections.abc import Callable

    from mcp.server.context import CallNext, HandlerResult, ServerRequestContext

    from .approval import Approvals
    from .guard import Guard
    from .link import Goal, RobotLink

__all__ = [
    "CANCEL_SETTLE_S",
    "MAX_TASKS",
    "POLL_INTERVAL_MS",
    "TASKS_EXTENSION",
    "TASK_TOOLS",
    "TASK_TTL_S",
    "GoalTask",
    "HostShare",
    "TaskStore",
    "TasksExtension",
]

TASKS_EXTENSION = "io.modelcontextprotocol/tasks"
"""The extension's identifier (``clientCapabilities.extensions``, ``capabilities.extensions``)."""
#: Tasks one store holds (running, or finished and not yet expired), and goals of its
#: tasks running at once (a host's share of them: ``HostShare``, D60).
MAX_TASKS = 64
#: Seconds a task lives from its creation (its ``ttlMs``); a goal running then is canceled.
TASK_TTL_S = 600.0
#: The polling interval a task suggests to its client, in ms.
POLL_INTERVAL_MS = 1000
#: Seconds ``tasks/cancel`` waits for a goal's end when its connection refused the cancel
#: as closed: a goal whose connection closes ends with it (D60).
CANCEL_SETTLE_S = 1.0


class HostShare(Protocol):
    """How many of a pool's slots each host may hold (as ``rwt_transports``' ``HostShares``).

    The rule of the server's connection slots, given to the store by the front end
    that knows its clients' hosts (D60); this package names it only.
    """

    def admits(self, host: str, taken: int, limit: int) -> bool:
        """Whether ``host`` may take a slot while ``taken`` of ``limit`` are taken."""
        ...

    def held(self, host: str) -> int:
        """Slots ``host`` holds."""
        ...

    def add(self, host: str) -> None:
        """``host`` took a slot."""
        ...

    def remove(self, host: str) -> None:
        """``host`` freed a slot."""
        ...


def _now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


@dataclass
class GoalTask:
    """One task: the goal it follows and the connection that holds the goal.

    ``released`` is set once the goal's connection may close: the goal ended,
    or the task expired (``TaskStore``). ``host``: the client's host, as the
    front end groups addresses (``""`` where it has one client); ``counted``:
    the task holds one of the store's running slots (its goal had not ended when
    the store last looked).
    """

    task_id: str
    record: Goal
    link: RobotLink
    report: Any  # (Goal) -> dict: the tool's report of the goal (``tools._report``)
    created: float
    host: str = ""
    counted: bool = True
    created_at: str = field(default_factory=_now_iso)
    last_updated_at: str = field(default_factory=_now_iso)
    released: anyio.Event = field(default_factory=anyio.Event)

    def wire(self) -> dict[str, Any]:
        """The task as ``tasks/get`` answers it: a ``DetailedTask`` of the extension's schema."""
        report: dict[str, Any] = self.report(self.record)
        state = str(report["state"])
        task: dict[str, Any] = {
            "taskId": self.task_id,
            "createdAt": self.created_at,
            "lastUpdatedAt": self.last_updated_at,
            "ttlMs": int(TASK_TTL_S * 1000),
            "pollIntervalMs": POLL_INTERVAL_MS,
            "statusMessage": json.dumps(report, ensure_ascii=False, separators=(",", ":")),
        }
        if state == "running":
            task["status"] = "working"
        elif state == "canceled":
            task["status"] = "cancelled"
        elif state.startswith("unknown"):
            task["status"] = "failed"
            task["error"] = {"code": -32603, "message": f"goal {self.record.handle.id}: {state}"}
        else:  # succeeded, aborted: the call completed; its result says how the goal ended
            task["status"] = "completed"
            text = task["statusMessage"]
            result = CallToolResult(
                content=[TextContent(type="text", text=text)], structured_content=report
            )
            task["result"] = result.model_dump(mode="json", by_alias=True, exclude_none=True)
        return task

    def touch(self) -> None:
        """Note a change of the goal (feedback, its end): ``lastUpdatedAt``."""
        self.last_updated_at = _now_iso()


class TaskStore:
    """The tasks of one front end, by id (``MAX_TASKS``, ``TASK_TTL_S``).

    A task takes a running slot before its goal is sent (``reserve``), and holds
    it while its goal runs: at most ``MAX_TASKS`` run at once, and with
    ``shares`` a host holds at most its share of them (D60).

    Args:
        clock: monotonic seconds (``anyio.current_time`` by default).
        new_id: makes a new task's ``taskId`` (a uuid4's 32 hex digits by default;
            a worker of ``rwt serve --workers`` names itself in it).
        shares: the hosts' shares of the running slots (``rwt serve --mcp``: the
            connection slots' rule, ``rwt_transports.admission.shares.HostShares``); None:
            one client (``rwt mcp``), no share.
    """

    def __init__(
        self,
        clock: Any = None,
        new_id: Callable[[], str] | None = None,
        shares: HostShare | None = None,
    ) -> None:
        self.tasks: OrderedDict[str, GoalTask] = OrderedDict()
        self.running = 0
        """Running slots taken: tasks whose goal runs, and goals being sent (``reserve``)."""
        self._clock = clock or anyio.current_time
        self._new_id = new_id or (lambda: uuid.uuid4().hex)
        self._shares = shares

    def reserve(self, host: str) -> None:
        """Take a running slot for a goal ``host`` is about to send as a task.

        Called before the goal is sent, so a refused task sends nothing; the
        slot is the task's once ``add`` makes it, else ``unreserve`` gives it back.

        Raises:
            ToolError: ``MAX_TASKS`` goals of tasks run (or are being sent), or
                ``host`` holds its share of them (``HostShare.admits``, D60).
        """
        self.expire()
        self._settle()
        if self.running >= MAX_TASKS:
            raise ToolError(
                f"{MAX_TASKS} tasks are running (MAX_TASKS): cancel one or wait for its end"
            )
        if self._shares is not None and not self._shares.admits(host, self.running, MAX_TASKS):
            raise ToolError(
                f"this host's {self._shares.held(host)} running tasks are its share of the "
                f"{MAX_TASKS} (MAX_TASKS, {self.running} running): cancel one or wait for its end"
            )
        self.running += 1
        if self._shares is not None:
            self._shares.add(host)

    def unreserve(self, host: str) -> None:
        """Give back a slot ``reserve`` took for ``host`` whose goal was not sent."""
        self.running -= 1
        if self._shares is not None:
            self._shares.remove(host)

    def add(self, record: Goal, link: RobotLink, report: Any, host: str = "") -> GoalTask:
        """A new task following ``record``, a goal sent on ``link`` for ``host``.

        It holds the running slot ``reserve`` took for ``host``. A store holding
        ``MAX_TASKS`` tasks forgets its oldest finished one (there is one: the
        slots bound the running ones).
        """
        if len(self.tasks) >= MAX_TASKS:
            finished = next((t for t in self.tasks.values() if t.record.done.is_set()), None)
            if finished is not None:
                self._drop(finished)
        task = GoalTask(self._new_id(), record, link, report, self._clock(), host=host)
        self.tasks[task.task_id] = task

        def changed(_values: object = None) -> None:
            task.touch()

        record.listeners.append(changed)
        return task

    def _settle(self) -> None:
        """Free the running slots of the tasks whose goal ended."""
        for task in self.tasks.values():
            if task.counted and task.record.done.is_set():
                self._uncount(task)

    def _uncount(self, task: GoalTask) -> None:
        task.counted = False
        self.unreserve(task.host)

    def get(self, task_id: str) -> GoalTask:
        """The task ``task_id``.

        Raises:
            MCPError: no such task (never made, or expired): ``INVALID_PARAMS``.
        """
        self.expire()
        task = self.tasks.get(task_id)
        if task is None:
            raise MCPError(INVALID_PARAMS, f"no task {task_id[:64]!r} (unknown, or expired)")
        return task

    def expire(self) -> None:
        """Forget the tasks past ``TASK_TTL_S``; a goal still running is canceled."""
        now = self._clock()
        for task in [t for t in self.tasks.values() if now - t.created >= TASK_TTL_S]:
            if not task.record.done.is_set():  # sent from the robot's task group
                task.link.robot.spawn(functools.partial(_cancel_quietly, task.link, task.record))
            self._drop(task)

    def _drop(self, task: GoalTask) -> None:
        self.tasks.pop(task.task_id, None)
        if task.counted:
            self._uncount(task)
        task.released.set()

    async def hold(self, task: GoalTask) -> None:
        """Wait until ``task``'s goal ends or the task expires, then release it.

        A goal still running at the task's expiry is canceled on its connection,
        sent before the connection is let go.
        """
        remaining = task.created + TASK_TTL_S - self._clock()
        with anyio.move_on_after(max(remaining, 0.0)):
            await task.record.done.wait()
        self.expire()
        if not task.record.done.is_set():
            with anyio.move_on_after(1.0):
                await _cancel_quietly(task.link, task.record)
        if task.record.done.is_set():
            task.touch()
        task.released.set()


async def _cancel_quietly(link: RobotLink, record: Goal) -> None:
    """Ask for the goal's cancel; a robot gone or refusing leaves its end to the robot."""
    with contextlib.suppress(RwtError, ToolError):
        await link.cancel(record)


class _TaskIdParams(RequestParams):
    """``tasks/get`` and ``tasks/cancel``'s params: ``{taskId}``."""

    task_id: str = Field(alias="taskId", max_length=128)


class _UpdateParams(_TaskIdParams):
    """``tasks/update``'s params: ``{taskId, inputResponses}``."""

    input_responses: dict[str, Any] = Field(alias="inputResponses", default_factory=dict)


def takes_tasks(ctx: ServerRequestContext[Any, Any]) -> bool:
    """Whether the request's client takes tasks: 2026-07-28 and the extension declared."""
    if ctx.protocol_version not in MODERN_PROTOCOL_VERSIONS:
        return False  # a task handle is 2026-era vocabulary (the SDK's rule)
    capabilities = ctx.session.client_capabilities
    declared = capabilities.extensions if capabilities is not None else None
    return bool(declared) and TASKS_EXTENSION in (declared or {})


class TasksExtension(Extension):
    """The Tasks extension on one MCP server (a session's, a request's).

    Args:
        store: the front end's tasks.
        link: this server's connection (goals it starts live on it).
        guard: this server's rules (``tasks/cancel`` is ``cancel_action_goal``'s call).
        start_goal: ``async (arguments, before_send) -> Goal``: admits and sends a
            goal of ``send_action_goal``'s arguments, calling ``before_send()`` (which
            may raise ``ToolError``) once they passed, before the goal is sent
            (``tools.RobotTools.start_goal``).
        report: ``(Goal) -> dict``: the goal as the tool reports it (``tools.goal_report``).
        host: the client's host, as the front end groups addresses for its share
            of the running tasks (``TaskStore.reserve``); ``""``: its one client.
    """

    identifier = TASKS_EXTENSION

    def __init__(
        self,
        store: TaskStore,
        link: RobotLink,
        guard: Guard,
        start_goal: Any,
        report: Any,
        host: str = "",
    ) -> None:
        self.store, self.link, self.guard, self.start_goal = store, link, guard, start_goal
        self.report, self.host = report, host
        self.started: list[GoalTask] = []
        self.approvals: Approvals | None = None
        """The calls that wait for a person: such a goal is asked for first, as the tool's."""

    def methods(self) -> list[MethodBinding]:
        """``tasks/get``, ``tasks/update``, ``tasks/cancel``."""
        return [
            MethodBinding("tasks/get", _TaskIdParams, self._get),
            MethodBinding("tasks/update", _UpdateParams, self._update),
            MethodBinding("tasks/cancel", _TaskIdParams, self._cancel),
        ]

    async def intercept_tool_call(
        self,
        params: CallToolRequestParams,
        ctx: ServerRequestContext[Any, Any],
        call_next: CallNext,
    ) -> HandlerResult:
        """A task for a ``TASK_TOOLS`` call of a client that takes tasks; else the call."""
        if params.name not in TASK_TOOLS or not takes_tasks(ctx):
            return await call_next(ctx)
        approvals = self.approvals
        if approvals is not None and approvals.target(params.name, dict(params.arguments or {})):
            return await call_next(ctx)  # a person's yes first (docs/safety.md): not a task
        reserved = False

        def reserve() -> None:  # the arguments passed: a running slot, or the refusal
            nonlocal reserved
            try:
                self.store.reserve(self.host)
            except ToolError as exc:
                now = self.guard.clock()
                log_refused(
                    client=self.guard.client,
                    op=params.name,
                    rule="MAX_TASKS",
                    reason=str(exc),
                    now=now,
                )
                raise ToolError(f"{params.name}: {exc}") from None
            reserved = True

        record: Goal | None = None
        try:
            record = await self.start_goal(dict(params.arguments or {}), reserve)
        except (ToolError, ValidationError) as exc:
            text = f"Error executing tool {params.name}: {exc}"
            return CallToolResult(content=[TextContent(type="text", text=text)], is_error=True)
        finally:
            if reserved and record is None:  # refused or failed after its slot: nothing sent
                self.store.unreserve(self.host)
        assert record is not None  # sent: else returned above
        task = self.store.add(record, self.link, self.report, self.host)
        self.started.append(task)
        return {"resultType": "task", **_handle(task)}

    async def hold(self) -> None:
        """Wait until the tasks this server started release their connection."""
        for task in self.started:
            await self.store.hold(task)

    async def _get(self, ctx: ServerRequestContext[Any, Any], params: _TaskIdParams) -> Any:
        self._rated("tasks/get")
        return {"resultType": "complete", **self.store.get(params.task_id).wire()}

    async def _update(self, ctx: ServerRequestContext[Any, Any], params: _UpdateParams) -> Any:
        self.store.get(params.task_id)
        raise MCPError(INVALID_PARAMS, "a goal's task asks for no input: nothing to update")

    async def _cancel(self, ctx: ServerRequestContext[Any, Any], params: _TaskIdParams) -> Any:
        """Cancel the task's goal; the answer is the task as it stands (D60).

        The extension's acknowledgement (``resultType: "complete"``) carries the
        task's fields, as ``tasks/get`` answers them: ``working`` while the cancel
        is on its way, the goal's end where it ended first.
        """
        task = self.store.get(params.task_id)
        record = task.record
        try:
            # any connection the rules allow may cancel it (D35); it goes through the
            # goal's own, where its id names it alone (other connections' goals may
            # have the same id, and a cancel from elsewhere names the newest)
            self.guard.admit("cancel_action_goal", {"action": record.action, "goal_id": ""})
            if not record.done.is_set():
                await task.link.cancel(record)
        except GraphError:
            pass  # its goal is no longer in flight: it ended, as ``tasks/get`` says
        except RwtError as exc:
            # the goal's connection closed: its goal ended with it, or is ending
            with anyio.move_on_after(CANCEL_SETTLE_S):
                await record.done.wait()
            if not record.done.is_set():
                raise MCPError(INVALID_PARAMS, f"tasks/cancel: {exc}") from None
        except ToolError as exc:
            raise MCPError(INVALID_PARAMS, f"tasks/cancel: {exc}") from None
        return {"resultType": "complete", **task.wire()}

    def _rated(self, request: str) -> None:
        try:
            self.guard.check_rate(request)
        except ToolError as exc:
            raise MCPError(INVALID_PARAMS, str(exc)) from None


def _handle(task: GoalTask) -> dict[str, Any]:
    """The ``Task`` fields of a new task (``CreateTaskResult`` without ``resultType``)."""
    return {
        "taskId": task.task_id,
        "status": "working",
        "createdAt": task.created_at,
        "lastUpdatedAt": task.last_updated_at,
        "ttlMs": int(TASK_TTL_S * 1000),
        "pollIntervalMs": POLL_INTERVAL_MS,
    }
