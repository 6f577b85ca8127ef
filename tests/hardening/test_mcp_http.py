"""``rwt serve --mcp`` against hostile HTTP clients (docs/mcp.md, docs/limits.md, D40).

- Each request in flight holds a socket. Before, only the MCP session counted
  against ``--max-connections``: one host within its share held a request socket
  per call (sessions x 8), ran a real ``rwt serve`` out of descriptors (EMFILE:
  nothing was accepted until the calls ended) and a WebSocket client of another
  host waited. Now each socket beyond a session's own slots takes a slot, within
  the host's share, or gets 503; the WebSocket client gets in at once.
- MCP sessions count against their host's share from the first (they hold no
  socket, so a ``--max-connections`` derived from the descriptors bound them late),
  and end after ``--idle-timeout`` without a request in flight (before: 600 s
  whatever the option said).
- A POST without a session id that is not ``initialize`` is refused before a
  session is built for it (before: a whole session, ~40 ms of CPU, then 400).
- Hostile bodies (JSON 100,000 deep, a 5,000-digit integer, bytes that are not
  UTF-8) get 400 with a JSON-RPC parse error, and the log no traceback (before:
  500 and two ERROR lines with a traceback each).

The official MCP client (Streamable HTTP) is the agent; raw HTTP (httpx) the attacker.
Every client is on loopback: 127.0.0.1 is the hog, 127.0.0.2 another host.
"""

from __future__ import annotations

import json
import logging
import subprocess
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import httpx
import httpx2
import pytest
from anyio.streams.buffered import BufferedByteReceiveStream
from websockets.asyncio.client import connect

from rwt import Graph, RosbridgeServer, ServerConfig
from tests.hardening.test_fd_exhaustion import ENV, limited_rwt

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp import ClientSession
from mcp.client.streamable_http import streamable_http_client

from rwt_transports.http.mcp import MAX_REQUESTS_IN_FLIGHT, SESSION_SLOTS
from rwt_transports.http.mcp_options import McpOptions
from tests.agents.test_mcp_safety import ACCEPT, INITIALIZE

pytestmark = pytest.mark.anyio

WAIT_S = 30  # a bound on a hang, not a speed requirement
INITIALIZED = {"jsonrpc": "2.0", "method": "notifications/initialized"}
SET_LEVEL = {"op": "set_level", "level": "info", "id": "served"}
ONLY_INITIALIZE = "only an initialize request opens a session"


@asynccontextmanager
async def serving(**fields: Any) -> AsyncIterator[tuple[str, RosbridgeServer]]:
    """An in-process server with ``--mcp`` (``fields`` of its config): its /mcp URL."""
    config = ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions(), **fields)
    server = RosbridgeServer(Graph(), config)
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield url.replace("ws://", "http://") + "/mcp", server
        tg.cancel_scope.cancel()


@asynccontextmanager
async def agent(endpoint: str, *, terminate: bool = True) -> AsyncIterator[ClientSession]:
    """The official MCP client, initialized (``terminate``: it DELETEs its session at the end)."""
    http = httpx2.AsyncClient(timeout=WAIT_S)
    async with (
        http,
        streamable_http_client(endpoint, http_client=http, terminate_on_close=terminate) as (
            read,
            write,
        ),
        ClientSession(read, write) as session,
    ):
        await session.initialize()
        yield session


async def open_raw(http: httpx.AsyncClient, endpoint: str) -> dict[str, str] | None:
    """Open a session with raw requests; its headers, or None if refused (503)."""
    opened = await http.post(endpoint, json=INITIALIZE, headers=ACCEPT)
    if opened.status_code == 503:
        return None
    assert opened.status_code == 200, opened.text
    session = {
        **ACCEPT,
        "Mcp-Session-Id": opened.headers["Mcp-Session-Id"],
        "Mcp-Protocol-Version": "2025-06-18",
    }
    assert (await http.post(endpoint, json=INITIALIZED, headers=session)).status_code == 202
    return session


def mcp_clients(server: RosbridgeServer) -> list[str]:
    return [client for client in server.sessions if client.startswith("mcp:")]


# ---- requests in flight hold descriptors: each is counted ----------------------------

FD_LIMIT = 64  # --max-connections 64 - 32 - 16 = 16; shares past 12
HOG_SESSIONS = 8  # x 8 calls in flight: 64 sockets, past the descriptors on main


async def held_call(
    http: httpx.AsyncClient, endpoint: str, session: dict[str, str], call_id: int, log: list[str]
) -> None:
    """An ``echo`` of a quiet topic for 20 s: its request holds a socket all along."""
    call = {
        "jsonrpc": "2.0",
        "id": call_id,
        "method": "tools/call",
        "params": {
            "name": "echo",
            "arguments": {"topic": "/quiet", "type": "std_msgs/msg/String", "timeout_s": 20},
        },
    }
    async with http.stream("POST", endpoint, json=call, headers=session) as reply:
        log.append(str(reply.status_code))  # its head: held (200) or refused
        if reply.status_code == 200:
            await reply.aread()
            log.append("ended")


async def test_calls_in_flight_cannot_run_the_server_out_of_descriptors(tmp_path: Path) -> None:
    log_path = tmp_path / "serve.log"
    with log_path.open("wb") as stderr:
        process = await anyio.open_process(
            [*limited_rwt(FD_LIMIT, FD_LIMIT), "--mcp", "--no-tf"],
            env=ENV,
            stdin=subprocess.DEVNULL,
            stderr=stderr,
        )
    async with process:
        try:
            assert process.stdout is not None
            with anyio.fail_after(WAIT_S):
                line = await BufferedByteReceiveStream(process.stdout).receive_until(b"\n", 1000)
            url = line.decode().strip().removeprefix("listening on ")
            endpoint = url.replace("ws://", "http://") + "/mcp"
            heads: list[str] = []
            limits = httpx.Limits(max_connections=None, max_keepalive_connections=0)
            async with (
                httpx.AsyncClient(timeout=60, limits=limits) as http,
                anyio.create_task_group() as tg,
            ):
                sessions = [await open_raw(http, endpoint) for _ in range(HOG_SESSIONS)]
                calls = 0
                for session in sessions:
                    for _ in range(MAX_REQUESTS_IN_FLIGHT if session is not None else 0):
                        calls += 1
                        tg.start_soon(held_call, http, endpoint, session, calls, heads)
                with anyio.move_on_after(10):  # on main, calls past the descriptors wait longer
                    while len(heads) < calls:
                        await anyio.sleep(0.05)
                # another host's WebSocket client, while the hog's calls are held
                async with connect(url, local_addr=("127.0.0.2", 0), open_timeout=60) as ws:
                    await ws.send(json.dumps(SET_LEVEL))
                    assert json.loads(await ws.recv())["id"] == "served"
                assert "ended" not in heads  # served while every held call still ran
                assert "200" in heads and "503" in heads  # the hog got its share, then 503
                tg.cancel_scope.cancel()
        finally:
            process.kill()  # also when an assertion failed: else aclose waits for it

    text = log_path.read_text()
    assert "event=accept_backoff" not in text  # never out of descriptors
    assert "reason='host share'" in text


async def test_a_call_past_the_slots_of_its_session_takes_one_or_gets_503() -> None:
    # 4 slots: the hog's session holds 2; its third call at once takes the third slot,
    # which is 3/4 of them: its fourth is past its host's share (the last slot is left
    # to a host holding none)
    async with (
        serving(max_connections=4) as (endpoint, _),
        httpx.AsyncClient(timeout=WAIT_S) as http,
        anyio.create_task_group() as tg,
    ):
        session = await open_raw(http, endpoint)
        assert session is not None
        heads: list[str] = []
        for call_id in range(SESSION_SLOTS + 1):
            tg.start_soon(held_call, http, endpoint, session, call_id, heads)
        with anyio.fail_after(WAIT_S):
            while len(heads) < SESSION_SLOTS + 1:
                await anyio.sleep(0.02)
        assert heads == ["200"] * (SESSION_SLOTS + 1)
        one_more: list[str] = []
        await held_call(http, endpoint, session, 99, one_more)
        assert one_more == ["503"]  # before, its socket was not counted: 200, and held
        ws_url = endpoint.replace("http://", "ws://").removesuffix("/mcp")
        async with connect(ws_url, local_addr=("127.0.0.2", 0)) as ws:  # another host
            await ws.send(json.dumps(SET_LEVEL))
            assert json.loads(await ws.recv())["id"] == "served"
        assert "ended" not in heads
        tg.cancel_scope.cancel()


# ---- sessions: a host's share from the first, --idle-timeout ----------------------------


async def test_a_host_holds_its_share_of_mcp_sessions_from_the_first(
    caplog: pytest.LogCaptureFixture,
) -> None:
    share = 2
    async with (
        serving(max_connections_per_host=share) as (endpoint, server),
        agent(endpoint) as first,
        agent(endpoint) as second,
        httpx.AsyncClient(timeout=WAIT_S) as http,
    ):
        # far below 3/4 of --max-connections, where the shares of sockets start
        refused = await http.post(endpoint, json=INITIALIZE, headers=ACCEPT)
        assert refused.status_code == 503 and "too many connections" in refused.text
        other = httpx.AsyncHTTPTransport(local_address="127.0.0.2")
        async with httpx.AsyncClient(timeout=WAIT_S, transport=other) as elsewhere:
            assert await open_raw(elsewhere, endpoint) is not None  # another host: its own share
        assert len(mcp_clients(server)) == share + 1
        assert (await first.list_tools()).tools and (await second.list_tools()).tools
    assert "reason='host share of mcp sessions' held=2 share=2" in caplog.text


async def test_an_mcp_session_ends_after_the_idle_timeout_without_a_request() -> None:
    async with serving(idle_timeout_s=1.0) as (endpoint, server):
        async with agent(endpoint, terminate=False) as session:
            assert (await session.list_tools()).tools
            (session_id,) = server.endpoints["mcp"].sessions
        # the client left without DELETE (its event stream closed): nothing in flight now
        with anyio.fail_after(WAIT_S):  # before: 600 s whatever --idle-timeout said
            while mcp_clients(server) or server.endpoints["mcp"].sessions:
                await anyio.sleep(0.1)
        async with httpx.AsyncClient(timeout=WAIT_S) as http:
            headers = {**ACCEPT, "Mcp-Session-Id": session_id}
            gone = await http.post(endpoint, json=INITIALIZED, headers=headers)
        assert gone.status_code == 404 and f"no MCP session {session_id}" in gone.text


# ---- requests refused before MCP sees them ---------------------------------------------


async def test_only_initialize_opens_a_session_and_others_are_refused_first(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    listing = {"jsonrpc": "2.0", "id": 2, "method": "tools/list"}
    async with serving() as (endpoint, server), httpx.AsyncClient(timeout=WAIT_S) as http:
        for body in (
            listing,
            INITIALIZED,
            [INITIALIZE],
            {"jsonrpc": "2.0", "method": "initialize"},
        ):
            refused = await http.post(endpoint, json=body, headers=ACCEPT)
            assert refused.status_code == 400
            error = refused.json()["error"]
            assert error["code"] == -32600
            assert error["message"] == f"Bad Request: no Mcp-Session-Id: {ONLY_INITIALIZE}"
        # no session was built for them: none connected, none was made and dropped
        assert "event=connect" not in caplog.text and not mcp_clients(server)
        assert await open_raw(http, endpoint) is not None
    assert "event=connect client=mcp:" in caplog.text


HOSTILE = {
    "JSON 100,000 deep": (b"[" * 100_000 + b"]" * 100_000, "Parse error: nesting deeper than 100"),
    "a 5,000-digit integer": (
        b'{"jsonrpc":"2.0","id":' + b"9" * 5000 + b',"method":"ping"}',
        "Parse error: invalid JSON: ",  # Python's own words for the digits follow
    ),
    "bytes that are not UTF-8": (
        b'{"jsonrpc":"2.0","id":1,"method":"' + bytes([0xFF, 0xFE]) + b'"}',
        "Parse error: invalid JSON: not UTF-8 at byte 34",
    ),
}


async def test_hostile_bodies_get_a_parse_error_and_no_traceback(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    async with serving() as (endpoint, _), httpx.AsyncClient(timeout=WAIT_S) as http:
        session = await open_raw(http, endpoint)
        assert session is not None
        for name, (body, why) in HOSTILE.items():
            for headers in (session, ACCEPT):  # in a session, and opening one
                refused = await http.post(endpoint, content=body, headers=headers)
                assert refused.status_code == 400, name
                error = refused.json()["error"]
                assert error["code"] == -32700 and error["message"].startswith(why), name
        ping = {"jsonrpc": "2.0", "id": 3, "method": "ping"}
        assert (await http.post(endpoint, json=ping, headers=session)).status_code == 200
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR or r.exc_info]
