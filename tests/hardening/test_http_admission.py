"""What a peer sends before its request is admitted stays within the server's bounds (D58).

An HTTP request on the WebSocket port (the HTTP API, ``/mcp``, ``/webrtc``,
``/version``) is read whole before its endpoint has the server admit it. Before, that
reading had no bound but ``--max-message-size`` a request: one address opened 250
sockets, each a 10 MiB body short of its last byte, and took the server's RSS from 49
MB to 3.1 GB, outside ``--memory-budget``, the host shares and the connection slots
(1.5 GB stayed after they closed); and four sockets sending chunked bodies of one
byte a chunk held the event loop through each read's thousands of chunks (a rosbridge
client's round trip went from 1 ms to 530 ms). Now (``rwt_transports.admission.pending``,
``http.endpoint.open_request``, docs/limits.md):

- what a request holds before it is admitted counts in the budget of input still
  arriving (``--max-fragment-memory``) and so in the memory budget, a host's requests
  hold at most a quarter of it, and a host reads at most ``--max-connections-per-host``
  requests at once: past either, 429 with ``Retry-After``; everything comes back when
  the sockets close;
- the reader yields by the work it did, so a body in 1-byte chunks is read whole and
  right while other clients are answered.

Every client is on loopback: 127.0.0.1 is the hog, 127.0.0.2 another host.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import anyio.lowlevel
import httpx
import pytest
from anyio.abc import SocketStream
from anyio.streams.buffered import BufferedByteReceiveStream
from websockets.asyncio.client import connect

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_transports.admission.pending import HOST_INPUT_SHARE, RETRY_AFTER_S
from rwt_transports.http.endpoint import MAX_HEAD_BYTES, READ_SLICE_EVENTS, open_request
from tests.support.cli import ENV, RWT_COLD, rwt_serve
from tests.support.realclients import REPO

pytestmark = pytest.mark.anyio

MiB = 1024 * 1024
WAIT_S = 30  # a bound on a hang, not a speed requirement
HOG = "127.0.0.1"
OTHER = "127.0.0.2"
FRAGMENT_MEMORY = 8 * MiB  # --max-fragment-memory: a host's share is 2 MiB
SHARE = FRAGMENT_MEMORY // HOST_INPUT_SHARE
PUBLISH = "/api/topics/chatter?type=std_msgs/msg/String"
INITIALIZE = {
    "jsonrpc": "2.0",
    "id": 1,
    "method": "initialize",
    "params": {
        "protocolVersion": "2025-06-18",
        "capabilities": {},
        "clientInfo": {"name": "chunked", "version": "0"},
    },
}
MCP_HEADERS = {"Accept": "application/json, text/event-stream", "Content-Type": "application/json"}


@asynccontextmanager
async def serving(graph: Graph | None = None, **fields: Any) -> AsyncIterator[RosbridgeServer]:
    """An in-process server on 127.0.0.1 (``fields`` of its config), serving."""
    config = ServerConfig(host="127.0.0.1", port=0, **fields)
    server = RosbridgeServer(graph or Graph(), config)
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        yield server
        tg.cancel_scope.cancel()


def port_of(server: RosbridgeServer) -> int:
    return int(server.urls["websocket"].rsplit(":", 1)[1])


async def wait_until(condition: Callable[[], bool]) -> None:
    """Wait (at most ``WAIT_S``: a hang guard) until ``condition()`` holds."""
    with anyio.fail_after(WAIT_S):
        while not condition():
            await anyio.sleep(0.01)


async def answer(stream: SocketStream) -> tuple[int, dict[str, str], str]:
    """The response the server wrote on ``stream``: status, headers (lower-case), body."""
    buffered = BufferedByteReceiveStream(stream)
    with anyio.fail_after(WAIT_S):
        head = (await buffered.receive_until(b"\r\n\r\n", 65536)).decode()
        status_line, *lines = head.split("\r\n")
        headers = {k.lower(): v.strip() for k, _, v in (line.partition(":") for line in lines)}
        body = await buffered.receive_exactly(int(headers.get("content-length", "0")))
    return int(status_line.split()[1]), headers, body.decode()


def post_head(path: str, length: int, extra: str = "") -> bytes:
    return (
        f"POST {path} HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
        f"Content-Length: {length}\r\n{extra}\r\n"
    ).encode()


async def post_held(stream: SocketStream, request: bytes) -> tuple[int, dict[str, str], str]:
    """Send ``request`` (its body short of its end) while reading the answer, if one comes.

    Read as it is sent: a refused request's socket is cut after its drain, and a reset
    loses what the client had not read yet. Waits (a request held gets no answer) until
    cancelled, or ``WAIT_S``.
    """
    async with anyio.create_task_group() as tg:

        async def send() -> None:
            with contextlib.suppress(anyio.BrokenResourceError, OSError):  # refused, cut
                await stream.send(request)

        tg.start_soon(send)
        got = await answer(stream)
        tg.cancel_scope.cancel()
    return got


async def rosbridge_call(port: int, source: str) -> dict[str, Any]:
    """A rosbridge client from ``source`` calling ``/rosapi/get_time``: its reply."""
    async with connect(f"ws://127.0.0.1:{port}", local_addr=(source, 0)) as ws:
        await ws.send(json.dumps({"op": "call_service", "service": "/rosapi/get_time", "id": 1}))
        with anyio.fail_after(WAIT_S):
            reply: dict[str, Any] = json.loads(await ws.recv())
    return reply


def other_host_client() -> httpx.AsyncClient:
    transport = httpx.AsyncHTTPTransport(local_address=OTHER)
    return httpx.AsyncClient(transport=transport, timeout=WAIT_S)


# ---- held bodies -----------------------------------------------------------------------


async def test_bodies_held_by_one_host_stay_within_its_share_and_come_back() -> None:
    graph = Graph()
    heard: list[str] = []
    graph.create_subscription("/chatter", lambda m: heard.append(m["data"]), "std_msgs/msg/String")
    async with serving(graph, max_fragment_memory=FRAGMENT_MEMORY) as server, AsyncExitStack() as s:
        port = port_of(server)
        memory_before = server.memory.used
        refusals: list[tuple[int, dict[str, str], str]] = []

        async def hold() -> None:  # a 1 MiB body short of its last byte, from the hog
            stream = await anyio.connect_tcp("127.0.0.1", port, local_host=HOG)
            s.push_async_callback(anyio.aclose_forcefully, stream)
            refusals.append(await post_held(stream, post_head(PUBLISH, MiB) + b"x" * (MiB - 1)))

        async with anyio.create_task_group() as tg:
            for _ in range(12):
                tg.start_soon(hold)
            # settled: each socket is either answered or held as a request being read
            await wait_until(lambda: len(refusals) + server.pending.reading(HOG) == 12)
            held = server.pending.held(HOG)
            assert server.pending.reading(HOG) >= 1  # some are held: they are not refused
            assert MiB < held <= SHARE
            # what they hold counts in the memory budget, through the input budget
            assert server.memory.used - memory_before >= held
            assert server.fragment_budget.used >= held
            assert len(refusals) >= 12 - SHARE // MiB
            for status, headers, text in refusals:
                assert status == 429
                assert headers["retry-after"] == str(RETRY_AFTER_S)
                assert "a quarter of --max-fragment-memory" in text
            # another host: served, its own body read whole
            async with other_host_client() as client:
                reply = await client.post(
                    f"http://127.0.0.1:{port}{PUBLISH}", json={"data": "y" * MiB}
                )
            assert reply.status_code == 200, reply.text
            await wait_until(lambda: bool(heard))
            assert heard == ["y" * MiB]
            # rosbridge clients, of another host and of the hog (a head whole in one read)
            assert "time" in (await rosbridge_call(port, OTHER))["values"]
            assert "time" in (await rosbridge_call(port, HOG))["values"]
            tg.cancel_scope.cancel()
        await s.aclose()  # the held sockets close
        await wait_until(lambda: server.pending.held(HOG) == 0)
        assert server.pending.reading(HOG) == 0
        assert server.fragment_budget.used == 0
        await wait_until(lambda: server.memory.used == memory_before)


def rss(pid: int) -> int:
    """The resident set of process ``pid`` now, bytes (VmRSS)."""
    return _status_field(pid, "VmRSS")


def peak_rss(pid: int) -> int:
    """The most resident memory of process ``pid`` since its mark was reset (VmHWM)."""
    return _status_field(pid, "VmHWM")


def reset_peak_rss(pid: int) -> None:
    """Start process ``pid``'s VmHWM again from its RSS now."""
    Path(f"/proc/{pid}/clear_refs").write_text("5")


def _status_field(pid: int, name: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{name}:"):
            return int(line.split()[1]) * 1024
    raise AssertionError(f"no {name} for {pid}")


RSS_SOCKETS = 30
RSS_BODY = 4 * MiB
RSS_FRAGMENT_MEMORY = 32 * MiB  # a host's share: 8 MiB
RSS_SLACK = 24 * MiB  # the sockets' buffers and the allocator's; unbounded, 120 MiB


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
async def test_rss_of_held_bodies_stays_within_the_share_and_is_given_back() -> None:
    """``rwt serve`` in a process of its own, as a user runs it: its RSS (VmHWM, VmRSS)."""
    args = ["serve", "--host", "127.0.0.1", "--port", "0", "--log-level", "error", "--no-tf"]
    args += ["--max-fragment-memory", str(RSS_FRAGMENT_MEMORY), "--heap-keep", "0"]
    env = {**ENV, "PYTHONPATH": str(REPO / "src")}
    process = await anyio.open_process(
        [*RWT_COLD, *args], env=env, stdin=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    async with process, AsyncExitStack() as stack:
        stack.callback(process.kill)
        assert process.stdout is not None
        with anyio.fail_after(WAIT_S):
            line = await BufferedByteReceiveStream(process.stdout).receive_until(b"\n", 1000)
        port = int(line.decode().rsplit(":", 1)[1])
        before = rss(process.pid)
        reset_peak_rss(process.pid)  # VmHWM from here
        answered: list[int] = []
        held: list[SocketStream] = []

        async def hold() -> None:
            stream = await anyio.connect_tcp("127.0.0.1", port, local_host=HOG)
            held.append(stream)
            request = post_head(PUBLISH, RSS_BODY) + b"x" * (RSS_BODY - 1)
            answered.append((await post_held(stream, request))[0])

        async with anyio.create_task_group() as tg:
            for _ in range(RSS_SOCKETS):
                tg.start_soon(hold)
            await wait_until(lambda: len(answered) >= RSS_SOCKETS - 2)
            tg.cancel_scope.cancel()  # the held ones get no answer
        assert set(answered) == {429}
        peak = peak_rss(process.pid) - before
        for stream in held:
            await anyio.aclose_forcefully(stream)
        # given back: the allocator keeps no freed heap (--heap-keep 0)
        await wait_until(lambda: rss(process.pid) - before < RSS_SLACK)
    print(f"peak {peak / MiB:.1f} MiB over the start")  # shown with -s
    assert peak < RSS_FRAGMENT_MEMORY // HOST_INPUT_SHARE + RSS_SLACK


# ---- how many requests a host reads at once ------------------------------------------------

PATHS = ["/api/topics/chatter?type=std_msgs/msg/String", "/mcp", "/webrtc", "/version"]


@pytest.mark.parametrize("path", PATHS)
async def test_a_host_reads_a_bounded_number_of_requests_on_every_endpoint(path: str) -> None:
    pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")
    pytest.importorskip("aiortc", reason="aiortc is not installed (the webrtc or test extra)")
    from rwt_transports.http.mcp_options import McpOptions  # noqa: PLC0415 (after the skips)
    from rwt_transports.webrtc.signalling import WebRtcOptions  # noqa: PLC0415

    fields = {"max_connections_per_host": 2, "mcp": McpOptions(), "webrtc": WebRtcOptions()}
    async with serving(**fields) as server, AsyncExitStack() as stack:
        port = port_of(server)
        for _ in range(2):  # two requests whose bodies are on their way
            stream = await anyio.connect_tcp("127.0.0.1", port, local_host=HOG)
            stack.push_async_callback(anyio.aclose_forcefully, stream)
            await stream.send(post_head(path, 100) + b"{")
        await wait_until(lambda: server.pending.reading(HOG) == 2)
        third = await anyio.connect_tcp("127.0.0.1", port, local_host=HOG)
        stack.push_async_callback(anyio.aclose_forcefully, third)
        await third.send(post_head(path, 100) + b"{")
        status, headers, text = await answer(third)
        assert status == 429
        assert headers["retry-after"] == str(RETRY_AFTER_S)
        assert "this host has 2 requests being read already" in text
        assert "--max-connections-per-host 2" in text
        # another host reads its own
        other = await anyio.connect_tcp("127.0.0.1", port, local_host=OTHER)
        stack.push_async_callback(anyio.aclose_forcefully, other)
        await other.send(post_head(path, 2) + b"{}")
        assert (await answer(other))[0] != 429


async def test_a_client_waiting_to_send_its_body_is_told_when_it_may() -> None:
    """``Expect: 100-continue`` (curl's for large bodies): 100 once admitted to read it;
    a body that cannot be held is refused before it is sent."""
    async with serving(max_fragment_memory=FRAGMENT_MEMORY) as server:
        port = port_of(server)
        body = json.dumps({"data": "z" * 1000}).encode()
        async with await anyio.connect_tcp("127.0.0.1", port) as stream:
            await stream.send(post_head(PUBLISH, len(body), "Expect: 100-continue\r\n"))
            buffered = BufferedByteReceiveStream(stream)
            with anyio.fail_after(WAIT_S):
                interim = await buffered.receive_until(b"\r\n\r\n", 1000)
            assert interim.startswith(b"HTTP/1.1 100 ")
            await stream.send(body)
            with anyio.fail_after(WAIT_S):
                final = await buffered.receive_until(b"\r\n", 1000)
            assert final.startswith(b"HTTP/1.1 200 ")
        async with await anyio.connect_tcp("127.0.0.1", port) as stream:
            await stream.send(post_head(PUBLISH, SHARE + 1, "Expect: 100-continue\r\n"))
            status, headers, _ = await answer(stream)  # at once, nothing sent
        assert status == 429
        assert headers["retry-after"] == str(RETRY_AFTER_S)


async def test_a_websocket_head_is_bounded_and_other_clients_connect() -> None:
    async with serving() as server:
        port = port_of(server)
        async with await anyio.connect_tcp("127.0.0.1", port) as stream:
            await stream.send(b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n")
            filler = b"X-Filler: " + b"a" * 4000 + b"\r\n"
            for _ in range(MAX_HEAD_BYTES // len(filler) + 1):
                await stream.send(filler)
            status, _, text = await answer(stream)
        assert status == 431
        assert f"over {MAX_HEAD_BYTES} bytes" in text
        assert "time" in (await rosbridge_call(port, HOG))["values"]


# ---- 1-byte chunks -------------------------------------------------------------------------


def one_byte_chunks(data: bytes) -> bytes:
    """``data`` as a chunked body of one byte a chunk, with its last chunk."""
    return b"".join(b"1\r\n" + data[i : i + 1] + b"\r\n" for i in range(len(data))) + b"0\r\n\r\n"


class _OneRead:
    """A byte stream that gave everything in one read: nothing more, its writes kept."""

    def __init__(self) -> None:
        self.sent = b""

    async def receive(self, max_bytes: int = 65536) -> bytes:
        raise anyio.EndOfStream

    async def send(self, data: bytes) -> None:
        self.sent += data


async def test_the_reader_yields_by_work_done_not_by_reads() -> None:
    """A body of 6,000 chunks in one read: the event loop turns while it is parsed."""
    message = json.dumps({"data": "c" * 6000}).encode()
    head = b"POST /x HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n"
    turns = 0
    read = None

    async def other_client() -> None:  # another task of the loop, counting its turns
        nonlocal turns
        while read is None:
            turns += 1
            await anyio.lowlevel.checkpoint()

    async def reader() -> None:
        nonlocal read
        read = await open_request(
            _OneRead(),  # type: ignore[arg-type]  (the two methods the reader uses)
            head + one_byte_chunks(message),
            limit=MiB,
            too_large="too large",
            allowed_origins=(),
            cors=[],
        )

    async with anyio.create_task_group() as tg:
        tg.start_soon(reader)
        tg.start_soon(other_client)
    assert read is not None
    assert read.body == message  # read whole and right
    assert turns >= len(message) // READ_SLICE_EVENTS - 1  # a turn at least every slice


async def chunker(port: int, path: str, sent: list[int]) -> None:
    """A raw socket of the hog sending 1-byte chunks to ``path`` until cancelled.

    Raises:
        anyio.BrokenResourceError: the server cut it off.
    """
    head = f"POST {path} HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n".encode()
    chunks = b"1\r\nx\r\n" * 1024
    async with await anyio.connect_tcp("127.0.0.1", port, local_host=HOG) as stream:
        await stream.send(head)
        while True:
            await stream.send(chunks)
            sent.append(len(chunks))


async def one_byte_at_a_time(data: bytes) -> AsyncIterator[bytes]:
    """``data`` for httpx to send as a chunked body, each byte a chunk of its own."""
    for i in range(len(data)):
        yield data[i : i + 1]


async def test_one_byte_chunks_are_read_right_while_others_are_answered() -> None:
    """``rwt serve --mcp`` in a process of its own; four sockets of the hog send 1-byte
    chunks that never end (read, never cut off), while httpx, an MCP request and
    rosbridge clients of another host are answered."""
    pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")
    text = "chunk by chunk " * 100
    # the hog's bodies never end: they would be cut at the handshake timeout (10 s)
    args = ("--port", "0", "--mcp", "--no-tf", "--handshake-timeout", "600")
    async with rwt_serve(*args) as (_, urls), AsyncExitStack() as stack:
        port = int(urls["ws"].rsplit(":", 1)[1])
        base = f"http://127.0.0.1:{port}"
        listener = await stack.enter_async_context(
            connect(f"ws://127.0.0.1:{port}", local_addr=(OTHER, 0))
        )
        subscribe = {"op": "subscribe", "topic": "/chatter", "type": "std_msgs/msg/String"}
        await listener.send(json.dumps(subscribe))
        sent: list[list[int]] = [[] for _ in range(4)]
        async with anyio.create_task_group() as tg:
            for each in sent:  # four sockets of the hog, never ending their bodies
                tg.start_soon(chunker, port, PUBLISH, each)
            await wait_until(lambda: all(sent))
            async with other_host_client() as client:
                body = json.dumps({"data": text}).encode()
                reply = await client.post(base + PUBLISH, content=one_byte_at_a_time(body))
                assert reply.status_code == 200, reply.text
                initialize = json.dumps(INITIALIZE).encode()
                mcp = await client.post(
                    base + "/mcp", content=one_byte_at_a_time(initialize), headers=MCP_HEADERS
                )
                assert mcp.status_code == 200, mcp.text
                assert "Mcp-Session-Id" in mcp.headers
                assert (await client.get(base + "/version")).status_code == 200
            with anyio.fail_after(WAIT_S):
                published = json.loads(await listener.recv())
            assert published["msg"] == {"data": text}  # read whole and right
            for _ in range(5):
                assert "time" in (await rosbridge_call(port, OTHER))["values"]
            tg.cancel_scope.cancel()  # all that while the hog's bodies were still being read
