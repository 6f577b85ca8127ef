"""A 1 kHz subscriber with ``lifespan`` 0.2 s whose link stalls 5 s (D63), on WS, TCP and WebRTC.

The robot (``qos_stall_robot.py``, its own process) publishes ``/stream`` every
millisecond, 8 kB a message, each stamped with the wall-clock time it was published.
A client subscribes with ``qos: {"lifespan": 0.2}``, reads a while, then its link
stalls: it reads nothing for 5 s (WebRTC: its whole event loop stops, so its SCTP
acknowledges nothing either). At the moment it resumes (``resumed``) the test measures
what the buffers between the server's queue and the client hold, then reads on.

What the client sees is judged by the ages of the messages, from their stamps and
the client's clock (one machine, one clock), never by how long anything took: a
message published more than the lifespan before ``resumed`` ("stale") can only
have been taken from the server's queue before the link came back (after that, the
queue gives nothing older than the lifespan), so the stale messages fit in what the
buffers held at that moment (the allowance): the kernel's socket buffers, read
from ``/proc/net/tcp`` (the server's send queue and the client's receive queue),
plus the server's own buffers past its queue (the batch its writer took, the
transport's write buffer and one more batch, ``pump.BATCH_BYTES`` each); for
WebRTC, the data channel's buffer (``webrtc.SEND_HIGH_WATER_BYTES``), SCTP's window
(1 MiB in aiortc) and two batches. The stall must matter: far more was published
during it than the allowance. docs/limits.md ("Lifespan across a stalled link")
states the figures measured.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import anyio
import pytest
from anyio.streams.buffered import BufferedByteReceiveStream
from websockets.client import ClientProtocol
from websockets.frames import Frame, Opcode
from websockets.uri import parse_uri

from rwt_transports.pump import BATCH_BYTES
from tests.support.clients import HAS_AIORTC, connect_webrtc

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

pytestmark = pytest.mark.anyio

ROBOT = Path(__file__).with_name("qos_stall_robot.py")
SRC = Path(__file__).parents[2] / "src"
LIFESPAN_S = 0.2
STALL_S = 5.0
CLOCK_SLACK_S = 0.02  # the wall clock against the monotonic one, across two processes
SCTP_WINDOW_BYTES = 1024 * 1024  # aiortc's advertised receive window
CLIENT_RCVBUF = 64 * 1024  # the client's receive buffer, set before it connects
FRESH_WANTED = 300  # messages to read after the stall
READ_LIMIT_S = 60.0  # a failure bound, not a measurement
SUBSCRIBE = {"op": "subscribe", "topic": "/stream", "qos": {"lifespan": LIFESPAN_S}}


@dataclass
class Seen:
    """What a client read: (sequence number, stamp, bytes) of each message."""

    messages: list[tuple[int, float, int]] = field(default_factory=list)

    def take(self, text: str | bytes) -> None:
        op = json.loads(text)
        if op.get("op") == "publish":
            seq, stamp, _ = op["msg"]["data"].split("|", 2)
            self.messages.append((int(seq), float(stamp), len(text)))


@asynccontextmanager
async def _robot() -> AsyncIterator[dict[str, str]]:
    """Start the robot; yield its URLs by scheme (``ws``, ``tcp``)."""
    process = await anyio.open_process(
        [sys.executable, str(ROBOT)],
        env={**os.environ, "PYTHONPATH": str(SRC)},
        stdin=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        assert process.stdout is not None
        lines = BufferedByteReceiveStream(process.stdout)
        urls: dict[str, str] = {}
        with anyio.fail_after(30):
            while not {"ws", "tcp"} <= urls.keys():
                url = (
                    (await lines.receive_until(b"\n", 1000)).decode().removeprefix("listening on ")
                )
                urls[url.split("://")[0]] = url
        yield urls
    finally:
        process.kill()
        with anyio.fail_after(10):
            await process.aclose()


def _port(url: str) -> int:
    return int(url.rsplit(":", 1)[1].rstrip("/"))


def _kernel_queues(server_port: int, client_port: int) -> int:
    """The server socket's send queue plus the client socket's receive queue, bytes."""
    total = 0
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        fields = line.split()
        local, remote = (int(address.split(":")[1], 16) for address in fields[1:3])
        tx_queue, rx_queue = (int(part, 16) for part in fields[4].split(":"))
        if (local, remote) == (server_port, client_port):
            total += tx_queue
        elif (local, remote) == (client_port, server_port):
            total += rx_queue
    return total


class RawLink:
    """A client's TCP socket with a small receive buffer, read only when the client reads."""

    def __init__(self, url: str) -> None:
        self.server_port = _port(url)
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, CLIENT_RCVBUF)
        self.sock.connect(("127.0.0.1", self.server_port))
        self.sock.setblocking(False)
        self.client_port = self.sock.getsockname()[1]

    async def send(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            await anyio.wait_writable(self.sock)
            view = view[self.sock.send(view) :]

    async def receive(self) -> bytes:
        while True:
            await anyio.wait_readable(self.sock)
            try:
                data = self.sock.recv(1 << 20)
            except BlockingIOError:
                continue
            if not data:
                raise EOFError("the server closed the connection")
            return data

    def allowance(self) -> int:
        return _kernel_queues(self.server_port, self.client_port) + 3 * BATCH_BYTES


class TcpClient:
    """rosbridge over TCP: JSON in, JSON lines out."""

    def __init__(self, url: str, stack: AsyncExitStack) -> None:
        self.link, self.buffer = RawLink(url), b""
        stack.callback(self.link.sock.close)

    async def start(self) -> None:
        await self.link.send(json.dumps(SUBSCRIBE).encode())

    async def message(self) -> bytes:
        while b"\n" not in self.buffer:
            self.buffer += await self.link.receive()
        line, self.buffer = self.buffer.split(b"\n", 1)
        return line

    async def stall(self) -> None:
        await anyio.sleep(STALL_S)  # reads nothing meanwhile

    def allowance(self) -> int:
        return self.link.allowance() + len(self.buffer)


class WsClient:
    """A plain WebSocket client: websockets' own protocol over a socket read only on demand."""

    def __init__(self, url: str, stack: AsyncExitStack) -> None:
        self.link = RawLink(url)
        stack.callback(self.link.sock.close)
        self.protocol = ClientProtocol(parse_uri(url), max_size=None)
        self.frames: list[Frame] = []

    async def start(self) -> None:
        self.protocol.send_request(self.protocol.connect())
        await self._flush()
        while self.protocol.handshake_exc is None and self.protocol.state.name == "CONNECTING":
            await self._read()
        self.protocol.send_text(json.dumps(SUBSCRIBE).encode())
        await self._flush()

    async def _flush(self) -> None:
        for data in self.protocol.data_to_send():
            if data:
                await self.link.send(data)

    async def _read(self) -> None:
        self.protocol.receive_data(await self.link.receive())
        for event in self.protocol.events_received():
            if isinstance(event, Frame) and event.opcode in (Opcode.TEXT, Opcode.BINARY):
                self.frames.append(event)
        await self._flush()  # pongs

    async def message(self) -> bytes:
        while not self.frames:
            await self._read()
        return bytes(self.frames.pop(0).data)

    async def stall(self) -> None:
        await anyio.sleep(STALL_S)

    def allowance(self) -> int:
        return self.link.allowance() + sum(len(frame.data) for frame in self.frames)


class RtcClient:
    """An aiortc peer on the ``rosbridge`` data channel, in this process."""

    def __init__(self, url: str, stack: AsyncExitStack) -> None:
        self.base = "http://" + url.split("://", 1)[1].rstrip("/")
        self.stack = stack

    async def start(self) -> None:
        self.client = await connect_webrtc(self.base, self.stack, "webrtc")
        await self.client.send(SUBSCRIBE)

    async def message(self) -> str | bytes:
        return await self.client.inbox.receive()  # type: ignore[no-any-return]

    async def stall(self) -> None:
        time.sleep(STALL_S)  # noqa: ASYNC251 (the link stalls: this peer's loop stops)

    def allowance(self) -> int:
        from rwt_transports.webrtc.channel import SEND_HIGH_WATER_BYTES  # noqa: PLC0415 (aiortc's)

        return SEND_HIGH_WATER_BYTES + SCTP_WINDOW_BYTES + 2 * BATCH_BYTES


async def _judge(client: TcpClient | WsClient | RtcClient) -> dict[str, float]:
    """Read, stall, measure at the resume, read on; the figures of the run."""
    before = Seen()
    with anyio.fail_after(READ_LIMIT_S):
        await client.start()
        while len(before.messages) < 200:  # flowing: the subscription is in place
            before.take(await client.message())
    await client.stall()
    resumed, allowance = time.time(), client.allowance()
    after = Seen()
    with anyio.fail_after(READ_LIMIT_S):
        while sum(stamp >= resumed - LIFESPAN_S for _, stamp, _ in after.messages) < FRESH_WANTED:
            after.take(await client.message())
    cutoff = resumed - LIFESPAN_S - CLOCK_SLACK_S
    stale = [(seq, size) for seq, stamp, size in after.messages if stamp < cutoff]
    first_fresh = next(seq for seq, stamp, _ in after.messages if stamp >= cutoff)
    published = first_fresh - before.messages[-1][0]  # during the stall, about
    return {
        "stale_messages": len(stale),
        "stale_bytes": sum(size for _, size in stale),
        "allowance_bytes": allowance,
        "published_during_stall_bytes": published * before.messages[-1][2],
        "oldest_stale_age_s": resumed - min((s for _, s, _ in after.messages), default=resumed),
    }


TRANSPORTS = [
    "ws",
    "tcp",
    pytest.param(
        "webrtc", marks=pytest.mark.skipif(not HAS_AIORTC, reason="aiortc is not installed")
    ),
]


@pytest.mark.parametrize("transport", TRANSPORTS)
async def test_nothing_older_than_the_lifespan_arrives_beyond_what_the_buffers_held(
    transport: str,
) -> None:
    async with _robot() as urls, AsyncExitStack() as stack:
        client: TcpClient | WsClient | RtcClient
        if transport == "tcp":
            client = TcpClient(urls["tcp"], stack)
        elif transport == "ws":
            client = WsClient(urls["ws"], stack)
        else:
            client = RtcClient(urls["ws"], stack)
        figures = await _judge(client)
    print(f"{transport}: {figures}")  # the figures docs/limits.md states (pytest -s)
    assert figures["published_during_stall_bytes"] > 2 * figures["allowance_bytes"]
    assert figures["stale_bytes"] <= figures["allowance_bytes"]
