"""The HTTP API's bounds with real clients (httpx): event streams under the host share, action
goals checked before their stream, the OpenAPI document fetched a bounded number at once."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager
from typing import Any

import anyio
import anyio.lowlevel
import anyio.to_thread
import httpx
import pytest

from rwt_graph.graph import Graph
from rwt_transports.http.api import DOCUMENT_FETCHES_PER_HOST
from rwt_transports.server import ServerConfig

from .support import api_server

pytestmark = pytest.mark.anyio

OTHER_HOST = "127.0.0.2"
"""Another host than the tests' 127.0.0.1 (all of 127/8 is this machine)."""


def _client(local_address: str = "127.0.0.1") -> httpx.AsyncClient:
    transport = httpx.AsyncHTTPTransport(local_address=local_address)
    return httpx.AsyncClient(transport=transport, timeout=30)


@asynccontextmanager
async def _stream(
    client: httpx.AsyncClient, url: str
) -> AsyncIterator[tuple[int, AsyncIterator[str]]]:
    """An event stream of ``url``: its status and its lines, open until the context ends."""
    async with client.stream("GET", url) as response:
        lines = response.aiter_lines()  # kept: a line iterator dropped closes the response
        yield response.status_code, lines


async def _first_data(lines: AsyncIterator[str]) -> str:
    async for line in lines:
        if line.startswith("data: "):
            return line
    raise AssertionError("the stream ended without a message")


async def test_a_hosts_event_streams_count_under_its_share_from_the_first() -> None:
    graph = Graph()
    publisher = graph.create_publisher("/odom", "std_msgs/msg/String", latch=True)
    publisher.publish({"data": "here"})
    config = ServerConfig(tf=False, max_connections_per_host=3)
    async with (
        api_server(graph, config) as (_, url),
        _client() as one,
        _client(OTHER_HOST) as other,
        AsyncExitStack() as held,
    ):
        events = f"{url}/api/topics/odom/events"
        for _ in range(3):  # the share, though almost every slot of the server is free
            status, lines = await held.enter_async_context(_stream(one, events))
            assert status == 200
            assert await _first_data(lines) == 'data: {"data":"here"}'
        refused = await one.get(events)
        assert refused.status_code == 503
        assert refused.json() == {"error": "too many connections"}
        # an action's stream is an event stream too
        goal = await one.post(f"{url}/api/actions/fib", json={"order": 1})
        assert goal.status_code == 503
        # a request that is not a stream still goes, and so does another host's stream
        assert (await one.get(f"{url}/api/topics")).status_code == 200
        async with _stream(other, events) as (status, lines):
            assert status == 200
            assert await _first_data(lines) == 'data: {"data":"here"}'
        await held.aclose()  # the host's streams end: its share comes back
        with anyio.fail_after(20):
            while True:
                async with _stream(one, events) as (status, lines):
                    if status == 200:
                        assert await _first_data(lines) == 'data: {"data":"here"}'
                        break
                await anyio.sleep(0.05)


async def test_an_action_goal_is_checked_before_its_stream_opens() -> None:
    graph = Graph()
    goals: list[dict[str, object]] = []

    async def fibonacci(goal: dict[str, object], context: object) -> dict[str, object]:
        goals.append(goal)
        return {"sequence": [0, 1]}

    graph.create_action_server("/fib", "example_interfaces/action/Fibonacci", fibonacci)
    async with api_server(graph) as (_, url), _client() as client:
        missing = await client.post(f"{url}/api/actions/nowhere", json={"order": 3})
        assert missing.status_code == 404
        assert missing.json() == {"error": "action /nowhere does not exist"}
        for body, problem in (
            ([3], "the body must be a JSON object (the goal)"),
            ([1, 2], "the body must be a JSON object (the goal)"),
            ({"order": "four"}, "expected int32, got str at $.order"),
            ({"order": 1.5}, "$.order"),
        ):
            answer = await client.post(f"{url}/api/actions/fib", json=body)
            assert answer.status_code == 400, answer.text
            assert answer.headers["content-type"] == "application/json"
            assert problem in answer.json()["error"]
        answer = await client.post(f"{url}/api/actions/fib", content=b"{not json")
        assert answer.status_code == 400
        assert goals == []  # none of them reached the action server
        done = await client.post(f"{url}/api/actions/fib", json={"order": 1})
        assert done.status_code == 200
        assert done.headers["content-type"] == "text/event-stream"
        assert done.text.startswith("event: result\n")
    assert goals == [{"order": 1}]


def _stalled_fetch(port: int) -> socket.socket:
    """A socket that asks for the document and reads nothing: its fetch stays in flight."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.settimeout(30)
    sock.connect(("127.0.0.1", port))
    sock.sendall(b"GET /openapi.json HTTP/1.1\r\nHost: x\r\n\r\n")
    assert sock.recv(12).startswith(b"HTTP/1.1 200")
    return sock


async def test_a_host_fetches_the_document_a_bounded_number_of_times_at_once() -> None:
    graph = Graph()
    for n in range(5000):  # a 12 MB document: more than the kernel holds for a stalled reader
        graph.create_publisher(f"/robot/t{n}", "nav_msgs/msg/Odometry")
    async with api_server(graph) as (_, url), _client() as one, _client(OTHER_HOST) as other:
        port = int(url.rsplit(":", 1)[1])
        stalled = [
            await anyio.to_thread.run_sync(_stalled_fetch, port)
            for _ in range(DOCUMENT_FETCHES_PER_HOST)
        ]
        try:
            refused = await one.get(f"{url}/openapi.json")
            assert refused.status_code == 429
            assert refused.headers["retry-after"] == "1"
            assert "DOCUMENT_FETCHES_PER_HOST" in refused.json()["error"]
            served = await other.get(f"{url}/openapi.json")
            assert served.status_code == 200
            assert "/api/topics/robot/t4999" in served.json()["paths"]
        finally:
            for sock in stalled:
                sock.close()
        with anyio.fail_after(20):  # the stalled fetches end with their sockets
            while (answer := await one.get(f"{url}/openapi.json")).status_code == 429:
                await anyio.sleep(0.05)
        assert answer.status_code == 200
        assert answer.headers["etag"] == served.headers["etag"]


def _slow_read(port: int, request: bytes) -> bytes:
    """The whole answer to ``request``, read 4 KB at a time with pauses: a slow reader."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.settimeout(30)
    sock.connect(("127.0.0.1", port))
    sock.sendall(request)
    data = bytearray()
    with sock:
        while chunk := sock.recv(4096):
            data += chunk
            time.sleep(0.0002)
    return bytes(data)


async def test_a_slow_reader_gets_an_action_stream_whole_to_its_result() -> None:
    """Events written from the publish path while the socket is full keep their order, and
    the stream still ends with the whole result (8 MB of feedback to a slow reader)."""
    graph = Graph()

    async def chatty(goal: dict[str, object], context: Any) -> dict[str, object]:
        for n in range(int(goal["order"])):  # type: ignore[call-overload]
            context.publish_feedback({"sequence": [n] * 2000})
            if n % 50 == 0:
                await anyio.lowlevel.checkpoint()
        return {"sequence": [7]}

    graph.create_action_server("/chatty", "example_interfaces/action/Fibonacci", chatty)
    async with api_server(graph) as (_, url):
        port = int(url.rsplit(":", 1)[1])
        body = b'{"order": 1000}'
        request = (
            b"POST /api/actions/chatty HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
            b"Content-Length: %d\r\n\r\n%s" % (len(body), body)
        )
        for _ in range(3):
            answer = await anyio.to_thread.run_sync(_slow_read, port, request)
            assert answer.startswith(b"HTTP/1.1 200 OK")
            events = answer.partition(b"\r\n\r\n")[2].split(b"\n\n")
            assert events[-1] == b""  # the stream ended after a whole event
            assert all(e.startswith(b"event: feedback\ndata: {") for e in events[:-2])
            firsts = [json.loads(e.partition(b"data: ")[2])["sequence"][0] for e in events[:-2]]
            assert firsts == sorted(set(firsts))  # in order, none twice (the oldest may drop)
            last = events[-2]
            assert last.startswith(b"event: result\ndata: "), last[:80]
            assert json.loads(last.partition(b"data: ")[2])["values"] == {"sequence": [7]}
