"""Goals as tasks: a host's share of the running tasks, and a cancel after a goal's end.

The official MCP SDK's client (2.x, the 2026-07-28 revision with the Tasks extension)
drives ``rwt serve --mcp`` (in-process) from two hosts on loopback: 127.0.0.1 holds
never-ending goals as tasks until its share of ``MAX_TASKS`` is full, and is refused
as a tool error naming the bound before its goal is sent; 127.0.0.2 still starts one
(docs/mcp.md, "Goals as tasks"; docs/limits.md; D60). A cancel of a task whose goal
ended first answers the task's end.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import anyio
import pytest

from rwt import RosbridgeServer, ServerConfig
from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.runtime import access as access_gate

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

import httpx2
from mcp import Client
from mcp.client.streamable_http import streamable_http_client
from mcp.types import CallToolResult, Request, TextContent

from rwt_mcp.guard import TOOL_CALLS_PER_S
from rwt_mcp.tasks import MAX_TASKS
from rwt_transports.admission.shares import SHARES_FROM
from rwt_transports.http.mcp_options import McpOptions
from tests.agents.test_mcp_revisions import (
    AUTO,
    FIB,
    HOLD_ORDER,
    TaskHandle,
    Tasks,
    TaskState,
    _TaskIdParams,
    robot,
    task_request,
)

pytestmark = pytest.mark.anyio

HOG, OTHER = "127.0.0.1", "127.0.0.2"  # two hosts: loopback answers on all of 127.0.0.0/8
WAIT_S = 60.0  # a guard against a hang, not a measure


@asynccontextmanager
async def serving() -> AsyncIterator[tuple[str, RosbridgeServer, list[str], list[str]]]:
    """``rwt serve --mcp`` of ``robot``: ``(ws url, server, goals started, goals canceled)``."""
    started: list[str] = []
    canceled: list[str] = []
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions())
    server = RosbridgeServer(robot(canceled, started), config)
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield url, server, started, canceled
        tg.cancel_scope.cancel()


@asynccontextmanager
async def agent(url: str, host: str) -> AsyncIterator[Client]:
    """A 2026-07-28 SDK client taking tasks, its requests sent from ``host``."""
    endpoint = "http://" + url.split("://", 1)[1] + "/mcp"
    http = httpx2.AsyncClient(
        transport=httpx2.AsyncHTTPTransport(local_address=host), timeout=WAIT_S
    )
    async with (
        http,
        Client(
            streamable_http_client(endpoint, http_client=http), mode=AUTO, extensions=[Tasks()]
        ) as client,
    ):
        assert client.protocol_version == "2026-07-28"
        yield client


def _text(result: CallToolResult) -> str:
    content = result.content[0]
    assert isinstance(content, TextContent)
    return content.text


async def start_task(client: Client, order: int) -> TaskHandle | CallToolResult:
    """``send_action_goal`` as a task: its handle, or the tool error.

    The host's calls of a tool are capped at ``TOOL_CALLS_PER_S``: a call over it is
    made again after its turn, as an agent told to wait does.
    """
    arguments = {"action": "/fibonacci", "type": FIB, "goal": {"order": order}}
    while True:
        answer = await client.session.call_tool("send_action_goal", arguments, allow_claimed=True)
        if not (isinstance(answer, CallToolResult) and "(TOOL_CALLS_PER_S)" in _text(answer)):
            assert isinstance(answer, TaskHandle | CallToolResult), answer
            return answer
        await anyio.sleep(1 / TOOL_CALLS_PER_S)


async def until(condition: Callable[[], bool]) -> None:
    """Wait until ``condition()`` holds (``WAIT_S`` at most)."""
    with anyio.fail_after(WAIT_S):
        while not condition():
            await anyio.sleep(0.02)


async def settled(client: Client, task_id: str) -> TaskState:
    """The task once it ended, polled as its ``pollIntervalMs`` allows (within the caps)."""
    with anyio.fail_after(WAIT_S):
        while True:
            state = await task_request(client, "tasks/get", task_id)
            assert isinstance(state, TaskState)
            if state.status != "working":
                return state
            await anyio.sleep(1 / TOOL_CALLS_PER_S)


async def test_a_host_past_its_share_of_tasks_is_refused_before_its_goal_is_sent(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="rwt")
    share = int(MAX_TASKS * SHARES_FROM)  # a host alone holds this many (HostShares)
    async with serving() as (url, _, started, canceled), agent(url, HOG) as hog:
        handles = [await start_task(hog, HOLD_ORDER) for _ in range(share)]
        assert all(isinstance(handle, TaskHandle) for handle in handles)
        await until(lambda: len(started) == share)
        # a new episode of the access log (the rate cap's refusals above had one), and a
        # turn of the rate cap, so the next call meets the share first
        monkeypatch.setattr(access_gate, "_episodes", EpisodeLog(access_gate.logger))
        await anyio.sleep(2 / TOOL_CALLS_PER_S)
        refused = await start_task(hog, HOLD_ORDER)
        assert isinstance(refused, CallToolResult) and refused.is_error
        assert _text(refused) == (
            "Error executing tool send_action_goal: send_action_goal: this host's 48 running"
            " tasks are its share of the 64 (MAX_TASKS, 48 running): cancel one or wait for"
            " its end"
        )
        async with agent(url, OTHER) as other:  # another host: its task is accepted
            accepted = await start_task(other, HOLD_ORDER)
            assert isinstance(accepted, TaskHandle), accepted
            await until(lambda: len(started) == share + 1)
            # sent after the refusal: had the refused goal been sent, it would be here too
            assert len(started) == share + 1
        # tasks that end give their slots back: with the other host's gone and one of
        # its own, the host is under its share again
        first = handles[0]
        assert isinstance(first, TaskHandle)
        for task_id in (accepted.task_id, first.task_id):
            await task_request(hog, "tasks/cancel", task_id)  # from any host (D35)
            assert (await settled(hog, task_id)).status == "cancelled"
        assert isinstance(await start_task(hog, HOLD_ORDER), TaskHandle)
        assert len(canceled) == 2
    lines = [r.getMessage() for r in caplog.records if "rule=MAX_TASKS" in r.getMessage()]
    assert len(lines) == 1, lines
    assert lines[0].startswith("event=access_denied client=mcp:127.0.0.1 op=send_action_goal")


async def test_a_cancel_after_the_goal_ended_answers_the_tasks_end() -> None:
    async with serving() as (url, server, _, canceled), agent(url, HOG) as client:
        handle = await start_task(client, 5)  # a short goal: it ends by itself
        assert isinstance(handle, TaskHandle), handle
        assert (await settled(client, handle.task_id)).status == "completed"
        # the goal's connection (its request's session) closed once the goal ended
        await until(lambda: not [c for c in server.sessions if c.startswith("mcp:")])
        request = Request[_TaskIdParams, str](
            method="tasks/cancel", params=_TaskIdParams(task_id=handle.task_id)
        )
        answer = await client.session.send_request(request, TaskState)
        assert answer.status == "completed"
        assert answer.task_id == handle.task_id
        end = answer.model_extra["result"]["structuredContent"]  # type: ignore[index]
        assert end["state"] == "succeeded"
        assert end["result"] == {"sequence": [0, 1, 1, 2, 3, 5]}
        assert not canceled  # nothing reached the action server
