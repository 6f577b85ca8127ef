"""A TCP proxy on 127.0.0.1 that delays what the server sends: a slow server, for the runner.

Every chunk the server sends reaches the client ``delay_s(chunk)`` seconds after
it came, never before the chunk ahead of it (a connection keeps its order, as a
slow server's would). ``stall``: the first chunk holding these bytes, and every
later one on its connection, is held until the connection ends: a server that
stalls one connection once. What the client sends goes through at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Callable

_READ_SIZE = 65536


class DelayingProxy:
    """Forwards 127.0.0.1:``port`` (the server) with its output delayed.

    Attributes:
        stalled: how many connections were stalled (0 or 1).
    """

    def __init__(
        self, port: int, delay_s: Callable[[bytes], float], stall: bytes | None = None
    ) -> None:
        self.port = port
        self.delay_s = delay_s
        self.stall = stall
        self.stalled = 0
        self.handlers: set[asyncio.Task[None]] = set()

    async def _connection(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self.handlers.add(task)
        task.add_done_callback(self.handlers.discard)
        try:
            up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.port)
        except OSError:
            writer.close()
            return
        queue: asyncio.Queue[tuple[float, bytes] | None] = asyncio.Queue()
        upstream = asyncio.create_task(_pipe(reader, up_writer))
        downstream = asyncio.create_task(self._delay(up_reader, queue))
        deliver = asyncio.create_task(_deliver(queue, writer))
        try:
            await asyncio.wait([upstream, deliver], return_when=asyncio.FIRST_COMPLETED)
        finally:
            for task in (upstream, downstream, deliver):
                task.cancel()
            await asyncio.gather(upstream, downstream, deliver, return_exceptions=True)
            for each in (writer, up_writer):
                each.close()

    async def _delay(
        self, reader: asyncio.StreamReader, queue: asyncio.Queue[tuple[float, bytes] | None]
    ) -> None:
        """Stamp each chunk from the server with the time it may go on."""
        loop = asyncio.get_running_loop()
        due = 0.0
        while chunk := await reader.read(_READ_SIZE):
            due = max(due, loop.time() + self.delay_s(chunk))
            if self.stall is not None and self.stalled == 0 and self.stall in chunk:
                self.stalled += 1
                due = math.inf
            queue.put_nowait((due, chunk))
        queue.put_nowait(None)


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    while chunk := await reader.read(_READ_SIZE):
        writer.write(chunk)
        await writer.drain()


async def _deliver(
    queue: asyncio.Queue[tuple[float, bytes] | None], writer: asyncio.StreamWriter
) -> None:
    loop = asyncio.get_running_loop()
    while (item := await queue.get()) is not None:
        due, chunk = item
        if due == math.inf:
            await asyncio.Event().wait()  # held until the connection ends
        await asyncio.sleep(max(0.0, due - loop.time()))
        writer.write(chunk)
        await writer.drain()


@contextlib.asynccontextmanager
async def delaying(
    port: int, delay_s: Callable[[bytes], float], stall: bytes | None = None
) -> AsyncIterator[tuple[DelayingProxy, int]]:
    """Run a ``DelayingProxy`` to ``port``; yields it and the port it listens on."""
    proxy = DelayingProxy(port, delay_s, stall)
    server = await asyncio.start_server(proxy._connection, "127.0.0.1", 0)
    try:
        yield proxy, server.sockets[0].getsockname()[1]
    finally:
        server.close()
        for handler in list(proxy.handlers):  # the connections the client left open
            handler.cancel()
        await asyncio.gather(*proxy.handlers, return_exceptions=True)
