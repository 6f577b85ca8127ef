"""``rwt serve --mcp --workers 2``: any worker answers, sessions and tasks are found from either.

The official MCP client drives a two-worker server the way agents do: a
2026-07-28 client whose every request is a connection of its own (the server
answers ``Connection: close``, so the kernel may hand each to either worker), and
2025-era clients whose sessions live in the worker that opened them. The ids
say which worker made them (``w0-``, ``w1-``): tasks and sessions of both
workers are made, and each is used from connections landing anywhere. A goal
started as a task on one worker is polled and canceled from a fresh client, and
the robot (a rosbridge client advertising the action on whichever worker it
reached) sees the cancel (docs/mcp.md, "Tasks and workers"). Relayed requests leave
no error in the server's log.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import select
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import h11
import httpx2
import pytest

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp import Client, ClientSession
from mcp.client.streamable_http import streamable_http_client

from rwt_client import Action, Ros
from rwt_client.ros import ServerGoal
from rwt_transports.http.mcp_siblings import PEER_PREAMBLE, McpSiblings
from tests.agents.test_mcp_revisions import (
    FIB,
    HOLD_ORDER,
    Tasks,
    TaskState,
    _goal_task,
    _settled,
    task_request,
)
from tests.zenoh.processes import rwt, started

pytestmark = pytest.mark.anyio

ATTEMPTS = 40  # each an even chance of either worker: both are met long before


@asynccontextmanager
async def modern(endpoint: str) -> AsyncIterator[Client]:
    """A 2026-07-28 client (``server/discover`` first) that takes tasks."""
    async with Client(endpoint, mode="auto", extensions=[Tasks()]) as client:
        assert client.protocol_version == "2026-07-28"
        yield client


async def _robot(url: str, canceled: list[str]) -> AsyncIterator[None]:
    """``/fibonacci`` served by a rosbridge client: long goals run until canceled."""
    async with Ros(url) as ros:

        async def fibonacci(goal: ServerGoal) -> dict[str, list[int]]:
            await goal.send_feedback({"sequence": [0, 1]})
            await goal.cancel_requested.wait()
            canceled.append(str(goal.id))
            goal.canceled()
            return {"sequence": [0, 1]}

        await Action(ros, "/fibonacci", FIB).advertise(fibonacci)
        yield


async def _tasks_on_both(endpoint: str) -> dict[str, str]:
    """A running goal's task made by each worker: ``{"w0": taskId, "w1": taskId}``."""
    made: dict[str, str] = {}
    for _ in range(ATTEMPTS):
        async with modern(endpoint) as client:
            task_id = await _goal_task(client, HOLD_ORDER)
            state = await task_request(client, "tasks/get", task_id)
        assert isinstance(state, TaskState)
        if state.status != "working":  # the action was not known on that worker yet
            await anyio.sleep(0.2)
            continue
        made.setdefault(task_id.split("-", 1)[0], task_id)
        if len(made) == 2:
            return made
    raise AssertionError(f"tasks made only by {sorted(made)} in {ATTEMPTS} goals")


async def _session_of_each(endpoint: str) -> set[str]:
    """2025-era sessions until each worker opened one; each serves four calls and ends."""
    owners: set[str] = set()
    for _ in range(ATTEMPTS):
        ids: set[str] = set()

        async def seen(response: httpx2.Response, ids: set[str] = ids) -> None:
            if "mcp-session-id" in response.headers:
                ids.add(response.headers["mcp-session-id"])

        http = httpx2.AsyncClient(event_hooks={"response": [seen]}, timeout=30)
        async with (
            http,
            streamable_http_client(endpoint, http_client=http) as (read, write),
            ClientSession(read, write) as agent,
        ):
            await agent.initialize()
            (session_id,) = ids
            owner = session_id.split("-", 1)[0]
            for _ in range(4):  # each request a connection: either worker takes it
                echoed = await agent.call_tool("echo", {"topic": "/client_count"})
                assert not echoed.is_error, echoed.content
            listing = await agent.list_tools()
            assert "send_action_goal" in {tool.name for tool in listing.tools}
        owners.add(owner)
        if owners == {"w0", "w1"}:
            return owners
    raise AssertionError(f"sessions opened only by {sorted(owners)}")


@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="--workers: Linux only")
async def test_both_revisions_and_tasks_across_two_workers() -> None:
    canceled: list[str] = []
    command = rwt("serve", "--port", "0", "--no-tf", "--mcp", "--workers", "2", cold=True)
    async with started(command, "parent") as parent:
        url = (await parent.line(within=60)).strip().removeprefix("listening on ")
        endpoint = "http://" + url.split("://", 1)[1] + "/mcp"
        with anyio.fail_after(120):
            async with asynccontextmanager(_robot)(url, canceled):
                made = await _tasks_on_both(endpoint)
                for task_id in made.values():  # each from fresh connections, either worker
                    async with modern(endpoint) as client:
                        state = await task_request(client, "tasks/get", task_id)
                        assert isinstance(state, TaskState) and state.status == "working"
                        report = json.loads(state.status_message or "{}")
                        assert report["action"] == "/fibonacci"
                        await task_request(client, "tasks/cancel", task_id)
                    async with modern(endpoint) as client:
                        ended = await _settled(client, task_id, every_s=0.25)  # the cap
                        assert ended.status == "cancelled", ended
                assert len(canceled) == 2  # the robot saw both cancels
                assert await _session_of_each(endpoint) == {"w0", "w1"}
                async with modern(endpoint) as client:  # a task of no worker: an error
                    with pytest.raises(Exception, match="no task"):
                        await task_request(client, "tasks/get", "w7-" + "0" * 32)
        log = parent.whole_stderr()
        assert "event=bug" not in log
        # relayed requests, streams whose client left included, leave no error: neither
        # asyncio's (a callback on a cancelled read) nor the SDK's (a write to a closed relay)
        assert " ERROR " not in log, log


def test_a_worker_knows_its_ids_from_the_others() -> None:
    place = McpSiblings.of_state("/run/rwt-workers-x/worker-1")
    assert place == McpSiblings("/run/rwt-workers-x", 1)
    assert McpSiblings.of_state("/run/rwt-workers-x/counts") is None
    mine, theirs = place.new_id(), McpSiblings("/f", 0).new_id()
    assert place.owner(mine) is None and place.owner(theirs) == 0
    for foreign in ("0123456789abcdef0123456789abcdef", "w0-short", "w0-" + "G" * 32, ""):
        assert place.owner(foreign) is None  # not a worker's id: answered here
    assert place.path(3) == "/run/rwt-workers-x/mcp-3.sock"


async def test_a_request_for_a_gone_worker_is_answered_where_it_came(tmp_path: Path) -> None:
    place = McpSiblings(str(tmp_path), 0)  # worker 1 has no socket: it died, or never was
    request = h11.Request(method="POST", target="/mcp", headers=[("host", "x")])
    client, server = await _socket_pair()
    async with client, server:
        assert not await place.forward(1, "127.0.0.1:1", request, b"{}", server)


async def test_a_forwarded_request_keeps_its_peer_and_body(tmp_path: Path) -> None:
    owner, sender = McpSiblings(str(tmp_path), 1), McpSiblings(str(tmp_path), 0)
    seen: list[tuple[str, bytes]] = []

    async def answer(stream: anyio.abc.ByteStream, head: bytes, peer: str) -> None:
        data = head
        while b"hello" not in data:
            data += await stream.receive()
        seen.append((peer, data))
        await stream.send(b"HTTP/1.1 200 OK\r\ncontent-length: 2\r\n\r\nok")

    body = b'{"hello": 1}'
    request = h11.Request(
        method="POST",
        target="/mcp",
        headers=[("host", "x"), ("transfer-encoding", "chunked")],  # read whole: re-framed
    )
    async with anyio.create_task_group() as tg:
        await tg.start(owner.serve, answer)
        client, server = await _socket_pair()
        async with client, server:
            with anyio.fail_after(10):
                assert await sender.forward(1, "[::1]:5000", request, body, server)
                assert (await client.receive()).endswith(b"ok")
        tg.cancel_scope.cancel()
    peer, data = seen[0]
    assert peer == "[::1]:5000"
    assert b"content-length: 12" in data.lower() and b"chunked" not in data.lower()
    assert data.endswith(body) and not data.startswith(PEER_PREAMBLE)


async def _socket_pair() -> tuple[anyio.abc.SocketStream, anyio.abc.SocketStream]:
    """Two ends of one loopback TCP connection (a client's socket, the server's)."""
    async with await anyio.create_tcp_listener(local_host="127.0.0.1") as listener:
        port = listener.extra(anyio.abc.SocketAttribute.local_port)
        client = await anyio.connect_tcp("127.0.0.1", port)
        server = await listener.listeners[0].accept()  # type: ignore[attr-defined]
    return client, server


async def test_a_client_leaving_a_relayed_stream_leaves_no_loop_error(tmp_path: Path) -> None:
    """The owner stops watching for the client's leaving in the loop turn it learns of it.

    The owner's answer is an event stream that watches its socket for the client's
    disconnect, as the MCP endpoint does (``_Exchange._receive``), and stops watching
    (a cancel) as soon as the socket is readable: when the client closes, the relay
    tells the owner (the end of the request stream). That cancel in the turn the
    socket became readable made asyncio log ``Exception in callback
    Future.set_result(None)`` under anyio's Unix streams; the owner's last writes
    then met a reader, not a broken pipe.
    """
    loop = asyncio.get_running_loop()
    errors: list[str] = []
    loop.set_exception_handler(lambda _loop, context: errors.append(context["message"]))
    owner, sender = McpSiblings(str(tmp_path), 1), McpSiblings(str(tmp_path), 0)
    wrote_after: list[bool] = []

    async def answer(stream: anyio.abc.ByteStream, head: bytes, peer: str) -> None:
        raw = stream.extra(anyio.abc.SocketAttribute.raw_socket)
        await stream.send(b"HTTP/1.1 200 OK\r\ncontent-type: text/event-stream\r\n\r\n")
        async with anyio.create_task_group() as tg:
            watching = anyio.CancelScope()

            async def watch() -> None:
                with watching, contextlib.suppress(anyio.EndOfStream):
                    while True:
                        await stream.receive()

            tg.start_soon(watch)
            while not select.select([raw], [], [], 0)[0]:  # each turn: has the client left?
                await anyio.lowlevel.checkpoint()
            watching.cancel()  # in the turn the socket became readable
        try:
            await stream.send(b"data: last\n\n")  # the stream's end, after the client left
            wrote_after.append(True)
        except (anyio.BrokenResourceError, OSError):
            wrote_after.append(False)

    request = h11.Request(method="GET", target="/mcp", headers=[("host", "x")])
    async with anyio.create_task_group() as tg:
        await tg.start(owner.serve, answer)
        for _ in range(20):
            client, server = await _socket_pair()
            async with server, anyio.create_task_group() as relay:
                relay.start_soon(sender.forward, 1, "127.0.0.1:1", request, b"", server)
                await client.receive()  # the stream began
                await client.aclose()  # the client leaves
            await anyio.sleep(0.01)  # the owner's answer ends
        tg.cancel_scope.cancel()
    assert wrote_after == [True] * 20
    assert errors == []
