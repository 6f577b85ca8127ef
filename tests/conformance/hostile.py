"""Small hostile servers (127.0.0.1) for the runner.

Each ``Behaviour`` is a WebSocket connection handler (the ``websockets`` library)
playing one way a server can attack its clients; ``serving`` runs one in a
thread of its own (its own event loop), so the runner can be driven in-process
or as an ``rwt conformance`` subprocess. ``SocketBehaviour``s play a server
below any protocol on plain sockets (``serving_sockets``): one that never reads,
reads a byte a second, or closes at once; the same port serves ``ws://`` and
``tcp://`` URLs.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import select
import socket
import threading
from collections.abc import Awaitable, Callable, Iterator
from contextlib import contextmanager

from websockets.asyncio.server import ServerConnection, serve
from websockets.http11 import Request
from websockets.protocol import State
from websockets.server import ServerProtocol

Behaviour = Callable[[ServerConnection], Awaitable[None]]

MiB = 1024 * 1024
DEEP = 200_000
"""Nesting of the deep JSON answers: far past Python's recursion limit."""
_WRITE_HIGH_WATER = MiB
"""Bytes the servers let wait in their own write buffer (their memory stays bounded too)."""


async def _drained(ws: ServerConnection) -> None:
    """Wait while the server's own write buffer is over ``_WRITE_HIGH_WATER``."""
    while ws.transport.get_write_buffer_size() > _WRITE_HIGH_WATER:
        await asyncio.sleep(0.01)


async def never_reads_and_pings(ws: ServerConnection) -> None:
    """Never read again after the handshake; ping without end (each ping wants a pong)."""
    ws.transport.pause_reading()
    ws.transport.get_extra_info("socket").setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    for n in itertools.count():
        if ws.protocol.state is not State.OPEN:  # the client gave up and cut it
            return
        ws.protocol.send_ping(n.to_bytes(8, "big") * 15)  # 120 bytes, under 125
        for data in ws.protocol.data_to_send():
            ws.transport.write(data)
        if n % 512 == 0:
            await asyncio.sleep(0)
            await _drained(ws)


async def deep_json(ws: ServerConnection) -> None:
    """Answer every frame with JSON nested ``DEEP`` levels."""
    deep = "[" * DEEP + "]" * DEEP
    async for _ in ws:
        await ws.send(deep)


def huge_frames(size: int) -> Behaviour:
    """Send frames of ``size`` bytes without end, as fast as the client takes them."""
    frame = json.dumps({"op": "publish", "topic": "/big", "msg": {"data": "A" * size}})

    async def handler(ws: ServerConnection) -> None:
        while True:
            await ws.send(frame)
            await _drained(ws)

    return handler


def closes_after(frames: int, code: int = 1011, reason: str = "bye") -> Behaviour:
    """Echo ``frames`` received frames, then close (``code``, ``reason``)."""

    async def handler(ws: ServerConnection) -> None:
        for _ in range(frames):
            await ws.send(await ws.recv())
        await ws.close(code, reason)

    return handler


async def silent(ws: ServerConnection) -> None:
    """Answer the handshake, read every frame, answer none."""
    async for _ in ws:
        pass


async def echo(ws: ServerConnection) -> None:
    """Send every frame back: the server answers, but not as rosbridge does."""
    async for message in ws:
        await ws.send(message)


def answers_first(connections: int) -> Behaviour:
    """Echo every frame on the first ``connections`` connections; be ``silent`` on later ones."""
    opened = itertools.count()

    async def handler(ws: ServerConnection) -> None:
        if next(opened) < connections:
            await echo(ws)
        else:
            await silent(ws)

    return handler


GARBAGE: tuple[str | bytes, ...] = (
    "not json at all",
    b"\xff\x00\xfe garbage",  # a binary frame cbor2 refuses
    '{"op": "publish", "topic": "/x", "msg": {"data": "\\ud800"}}',  # a lone surrogate
    "\ud800\udfff\x00",  # text the JSON decoder refuses, with surrogates and a NUL
    b"\x81" * 1000 + b"\x00",  # CBOR nested 1000 deep
)


async def garbage(ws: ServerConnection) -> None:
    """Answer every frame with ``GARBAGE``, a text frame that is not UTF-8 and a rosapi
    answer whose field names are a lone surrogate and a NUL."""
    async for message in ws:
        for frame in GARBAGE:
            if isinstance(frame, str):
                await ws.send(frame.encode("utf-8", "surrogatepass").decode("utf-8", "replace"))
            else:
                await ws.send(frame)
        ws.protocol.send_text(b'{"op": "publish", "topic": "/\xff\xfe"}')  # RFC 6455 8.1
        for data in ws.protocol.data_to_send():
            ws.transport.write(data)
        request = json.loads(message)
        answer = {
            "op": "service_response",
            "id": request.get("id"),
            "service": request.get("service"),
            "result": True,
            "values": {"typedefs": [{"type": "std_msgs/Header", "fieldnames": ["\ud800", "\x00"]}]},
        }
        await ws.send(json.dumps(answer))  # ensure_ascii: the surrogate goes out escaped


def answering(burst: Callable[[], list[tuple[bytes, bool]]]) -> Behaviour:
    """Answer every frame with ``burst()``: (bytes, binary) frames sent as they are,
    text frames included (not necessarily UTF-8)."""

    async def handler(ws: ServerConnection) -> None:
        async for _ in ws:
            for data, binary in burst():
                if binary:
                    ws.protocol.send_binary(data)
                else:
                    ws.protocol.send_text(data)
            for chunk in ws.protocol.data_to_send():
                ws.transport.write(chunk)
            await _drained(ws)

    return handler


RawBehaviour = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]


def greets_with(frame: str | bytes) -> RawBehaviour:
    """Accept the handshake and send ``frame`` in the same write as the 101 answer.

    A client reads both in one chunk (sans-IO ``ServerProtocol`` over a raw socket:
    the ``websockets`` server writes the answer and the handler's frames apart).
    """

    async def handler(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        protocol = ServerProtocol(max_size=None)
        events: list[object] = []
        try:
            while not events:
                protocol.receive_data(await reader.read(65536))
                events = list(protocol.events_received())
            request = events[0]
            assert isinstance(request, Request)
            protocol.send_response(protocol.accept(request))
            if isinstance(frame, str):
                protocol.send_text(frame.encode())
            else:
                protocol.send_binary(frame)
            writer.write(b"".join(protocol.data_to_send()))
            await writer.drain()
            await reader.read()  # until the client goes
        except ConnectionError:
            pass  # the client cut the connection: that is what it should do
        finally:
            writer.transport.abort()  # at once: no write buffer to flush to a gone client

    return handler


@contextmanager
def serving_raw(behaviour: RawBehaviour) -> Iterator[str]:
    """Run ``behaviour`` as a plain TCP server on 127.0.0.1 in a thread; yields a ws URL.

    Connections still open at the end are cancelled and awaited, so each handler
    closes its socket before the loop ends.
    """
    handlers: set[asyncio.Task[None]] = set()

    async def tracked(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        handlers.add(task)
        try:
            await behaviour(reader, writer)
        finally:
            handlers.discard(task)

    async def finish() -> None:
        for task in list(handlers):
            task.cancel()
        await asyncio.gather(*handlers, return_exceptions=True)
        await asyncio.sleep(0)  # the aborted transports' connection_lost callbacks

    with _in_thread(lambda: asyncio.start_server(tracked, "127.0.0.1", 0), finish) as url:
        yield url


@contextmanager
def _in_thread(
    start: Callable[[], Awaitable[asyncio.Server]], finish: Callable[[], Awaitable[None]]
) -> Iterator[str]:
    started = threading.Event()
    url: list[str] = []
    loop = asyncio.new_event_loop()
    stop = asyncio.Event()

    async def main() -> None:
        server = await start()
        url.append(f"ws://127.0.0.1:{server.sockets[0].getsockname()[1]}")
        started.set()
        await stop.wait()
        server.close()
        await finish()

    thread = threading.Thread(target=loop.run_until_complete, args=(main(),), daemon=True)
    thread.start()
    try:
        if not started.wait(30):
            raise RuntimeError("the hostile server did not start")
        yield url[0]
    finally:
        loop.call_soon_threadsafe(stop.set)
        thread.join(30)
        loop.close()


@contextmanager
def serving(behaviour: Behaviour, *, max_size: int | None = MiB) -> Iterator[str]:
    """Run ``behaviour`` as a WebSocket server on 127.0.0.1 in a thread; yields its URL."""
    started = threading.Event()
    url: list[str] = []
    loop = asyncio.new_event_loop()
    stop = asyncio.Event()

    async def main() -> None:
        async with serve(behaviour, "127.0.0.1", 0, max_size=max_size, ping_interval=None) as srv:
            url.append(f"ws://127.0.0.1:{srv.sockets[0].getsockname()[1]}")
            started.set()
            await stop.wait()
            srv.close(close_connections=False)
            for connection in list(srv.connections):
                connection.transport.abort()

    thread = threading.Thread(target=loop.run_until_complete, args=(main(),), daemon=True)
    thread.start()
    try:
        if not started.wait(30):
            raise RuntimeError("the hostile server did not start")
        yield url[0]
    finally:
        loop.call_soon_threadsafe(stop.set)
        thread.join(30)
        loop.close()


SocketBehaviour = Callable[[socket.socket, threading.Event], None]
"""Plays one accepted connection on a plain blocking socket, until the event is set."""

SMALL_RCVBUF = 4096
"""The listening socket's receive buffer, bytes (its connections inherit it): a
server that never reads holds little of what a client sends, so a client's sends
block soon (the kernel doubles the value and keeps a floor)."""


def never_reads(conn: socket.socket, stop: threading.Event) -> None:
    """Accept and never ``recv()``: the bytes a client sends pile up, then its sends block."""
    stop.wait()


def reads_a_byte_a_second(conn: socket.socket, stop: threading.Event) -> None:
    """Read one byte a second, answer nothing."""
    conn.settimeout(0.5)  # a recv waiting for the client still sees ``stop``
    while not stop.wait(1.0):
        try:
            if not conn.recv(1):
                return
        except TimeoutError:
            continue


def closes_at_once(conn: socket.socket, stop: threading.Event) -> None:
    """Close the connection as soon as it is accepted (``serving_sockets`` closes it)."""


@contextmanager
def serving_sockets(behaviour: SocketBehaviour) -> Iterator[str]:
    """Run ``behaviour`` on each connection to a plain TCP socket on 127.0.0.1; yields
    ``127.0.0.1:PORT``.

    The listening socket has ``SMALL_RCVBUF``; each connection gets a thread,
    which closes it when its behaviour returns. At the end every thread is told
    to stop and joined.
    """
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SMALL_RCVBUF)
    listener.bind(("127.0.0.1", 0))
    listener.listen()
    stop = threading.Event()
    threads: list[threading.Thread] = []

    def play(conn: socket.socket) -> None:
        try:
            behaviour(conn, stop)
        except OSError:
            pass  # the client cut the connection
        finally:
            conn.close()

    def accept() -> None:
        while not stop.is_set():
            ready, _, _ = select.select([listener], [], [], 0.1)
            if ready:
                conn, _ = listener.accept()
                thread = threading.Thread(target=play, args=(conn,), daemon=True)
                threads.append(thread)
                thread.start()

    acceptor = threading.Thread(target=accept, daemon=True)
    acceptor.start()
    try:
        yield f"127.0.0.1:{listener.getsockname()[1]}"
    finally:
        stop.set()
        acceptor.join(30)
        for thread in threads:
            thread.join(30)
        listener.close()
