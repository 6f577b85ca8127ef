"""Minimal rosbridge test clients for every transport, and an in-process server fixture.

Each client sends ops (or raw bytes) and reads JSON messages, reassembling
``fragment`` ops as real clients do. Every wait is bounded by the caller's
``anyio.fail_after``.
"""

from __future__ import annotations

import json
import os
import ssl
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field, replace
from typing import Any

import anyio
from anyio.abc import ByteStream
from websockets.asyncio.client import ClientConnection, connect

from rwt_transports.memory import MemoryConnection
from rwt_transports.server import RosbridgeServer, ServerConfig
from rwt_transports.udp.validation import CHALLENGE_TEXT, MIN_PROBE_BYTES, SESSION_CHALLENGE_TEXT
from rwt_transports.webrtc.signalling import WebRtcOptions

Message = dict[str, Any]


def is_op(name: str, **fields: object) -> Callable[[Message], bool]:
    """A predicate for ``Client.expect``: an op named ``name`` with these field values."""
    return lambda m: m.get("op") == name and all(m.get(k) == v for k, v in fields.items())


TRANSPORTS = ("memory", "ws", "tcp", "udp", "stdio")


def _webrtc_runs_here() -> bool:
    """aiortc is installed and the machine has an address besides loopback.

    aiortc's ICE (aioice) offers no 127.0.0.1 candidate: on a machine with only
    loopback no two peers can connect.
    """
    try:
        import aiortc  # noqa: F401, PLC0415 (optional: rwt-rosbridge[webrtc])
        import ifaddr  # noqa: PLC0415 (aioice's, so aiortc's, dependency)
    except ImportError:
        return False

    loopback = {"127.0.0.1", "::1"}
    return any(
        (ip.ip if isinstance(ip.ip, str) else ip.ip[0]) not in loopback
        for adapter in ifaddr.get_adapters()
        for ip in adapter.ips
    )


HAS_AIORTC = _webrtc_runs_here()
"""Whether ``running_server`` answers WebRTC offers and ``Harness.connect("webrtc")`` works."""

CONTRACT_TRANSPORTS = (*TRANSPORTS, "webrtc") if HAS_AIORTC else TRANSPORTS
"""The transports tests/transports/test_contract.py runs its contract over (``webrtc``: a
server on aiortc)."""

NATIVE_WEBRTC = "webrtc-native"
"""The contract's WebRTC transport on the native stack (D51): an aiortc peer, a server
whose ``running_server(webrtc_stack="native")`` answers with libdatachannel."""

REACTOR_WEBRTC = "webrtc-reactor"
"""The contract's WebRTC transport on the reactor stack (D70): an aiortc peer, a server
whose ``running_server(webrtc_stack="reactor")`` answers with libwebrtc."""


@dataclass
class Client:
    """Base: JSON in, JSON out, fragments reassembled (spec 3.1.1)."""

    name: str
    parts: dict[object, dict[int, str]] = field(default_factory=dict)
    backlog: list[Message] = field(default_factory=list)

    async def send_raw(self, data: bytes) -> None:
        raise NotImplementedError

    async def _receive_raw(self) -> bytes | str:
        raise NotImplementedError

    async def aclose(self) -> None:
        raise NotImplementedError

    async def send(self, op: Message) -> None:
        await self.send_raw(json.dumps(op).encode() + self.terminator)

    @property
    def terminator(self) -> bytes:
        """What ends a frame: a newline for line-framed stdio (harmless on TCP)."""
        return b"\n" if isinstance(self, StreamClient) else b""

    async def receive(self) -> Message:
        """The next whole message (fragments reassembled)."""
        while True:
            message = json.loads(await self._receive_raw())
            if message.get("op") != "fragment":
                return message  # type: ignore[no-any-return]
            parts = self.parts.setdefault(message["id"], {})
            parts[message["num"]] = message["data"]
            if len(parts) == message["total"]:
                del self.parts[message["id"]]
                return json.loads("".join(parts[i] for i in range(message["total"])))  # type: ignore[no-any-return]

    async def expect(self, predicate: Callable[[Message], bool]) -> Message:
        """Read until a message matches; keep the others in ``backlog``."""
        for i, message in enumerate(self.backlog):
            if predicate(message):
                return self.backlog.pop(i)
        while True:
            message = await self.receive()
            if predicate(message):
                return message
            self.backlog.append(message)


@dataclass
class MemoryClient(Client):
    connection: MemoryConnection | None = None

    async def send_raw(self, data: bytes) -> None:
        assert self.connection is not None
        await self.connection.send_frame(data)

    async def _receive_raw(self) -> bytes:
        assert self.connection is not None
        frame = await self.connection.receive_frame()
        return frame.encode() if isinstance(frame, str) else frame

    async def aclose(self) -> None:
        pass  # the server's context manager closes it


@dataclass
class WsClient(Client):
    ws: ClientConnection | None = None

    async def send_raw(self, data: bytes) -> None:
        assert self.ws is not None
        await self.ws.send(data.decode("utf-8", "replace"))

    async def _receive_raw(self) -> bytes | str:
        assert self.ws is not None
        return await self.ws.recv()

    async def aclose(self) -> None:
        assert self.ws is not None
        await self.ws.close()


@dataclass
class StreamClient(Client):
    """TCP (or TLS, or a stdio pipe pair): concatenated JSON in, JSON lines out."""

    stream: ByteStream | None = None
    buffer: bytes = b""

    async def send_raw(self, data: bytes) -> None:
        assert self.stream is not None
        await self.stream.send(data)

    async def _receive_raw(self) -> bytes:
        assert self.stream is not None
        while b"\n" not in self.buffer:
            self.buffer += await self.stream.receive()
        line, self.buffer = self.buffer.split(b"\n", 1)
        return line

    async def aclose(self) -> None:
        assert self.stream is not None
        await self.stream.aclose()


async def validate_udp(sock: Any) -> bytes:
    """The UDP address validation (docs/limits.md): a padded probe, then the token.

    A client without a token takes either challenge (a session its address still
    has, from a run before, is replaced).

    Returns:
        The prefix of every later datagram: the token and a newline.
    """
    while True:  # UDP loses datagrams: a probe without an answer is sent again
        await sock.send(b'{"op":"status"}'.ljust(MIN_PROBE_BYTES))
        with anyio.move_on_after(1.0):
            while True:
                reply = json.loads(await sock.receive())
                if reply.get("msg") in (CHALLENGE_TEXT, SESSION_CHALLENGE_TEXT):
                    return reply["id"].encode() + b"\n"  # type: ignore[no-any-return]


@dataclass
class UdpClient(Client):
    sock: Any = None
    prefix: bytes = b""  # the address-validation token and a newline

    async def send_raw(self, data: bytes) -> None:
        await self.sock.send(self.prefix + data)

    async def _receive_raw(self) -> bytes:
        return await self.sock.receive()  # type: ignore[no-any-return]

    async def aclose(self) -> None:
        await self.sock.aclose()


class PipeStream(ByteStream):
    """The client's end of a stdio session: writes to the server's stdin, reads its stdout."""

    def __init__(self, write_fd: int, read_fd: int) -> None:
        self.write_fd, self.read_fd = write_fd, read_fd
        os.set_blocking(read_fd, False)
        os.set_blocking(write_fd, False)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        while True:
            await anyio.wait_readable(self.read_fd)
            try:
                data = os.read(self.read_fd, max_bytes)
            except BlockingIOError:
                continue
            if not data:
                raise anyio.EndOfStream
            return data

    async def send(self, item: bytes) -> None:
        view = memoryview(item)
        while view:
            await anyio.wait_writable(self.write_fd)
            try:
                view = view[os.write(self.write_fd, view) :]
            except BlockingIOError:
                continue

    async def send_eof(self) -> None:
        os.close(self.write_fd)
        self.write_fd = -1

    async def aclose(self) -> None:
        for fd in (self.write_fd, self.read_fd):
            if fd >= 0:
                os.close(fd)
        self.write_fd = self.read_fd = -1


@dataclass
class WebRtcClient(Client):
    """A real WebRTC peer (aiortc) on the ``rosbridge`` data channel (docs/webrtc.md)."""

    channel: Any = None
    inbox: Any = None  # anyio receive stream of the channel's messages

    async def send_raw(self, data: bytes) -> None:
        self.channel.send(data.decode("utf-8", "replace"))  # text, as WsClient sends

    async def _receive_raw(self) -> bytes | str:
        return await self.inbox.receive()  # type: ignore[no-any-return]

    async def aclose(self) -> None:
        self.channel.close()


async def connect_webrtc(base: str, stack: AsyncExitStack, name: str) -> WebRtcClient:
    """Offer to ``base``/webrtc (an ``http://`` URL), open ``rosbridge``; closed with ``stack``."""
    import httpx  # noqa: PLC0415 (the test extra's; with aiortc only)
    from aiortc import (  # noqa: PLC0415 (optional: rwt-rosbridge[webrtc])
        RTCConfiguration,
        RTCPeerConnection,
        RTCSessionDescription,
    )

    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    stack.push_async_callback(pc.close)
    channel = pc.createDataChannel("rosbridge")
    sender, inbox = anyio.create_memory_object_stream[bytes | str](max_buffer_size=10_000)
    stack.callback(inbox.close)
    opened = anyio.Event()
    channel.on("open", opened.set)
    channel.on("message", sender.send_nowait)
    channel.on("close", sender.close)
    await pc.setLocalDescription(await pc.createOffer())
    async with httpx.AsyncClient(base_url=base) as http:
        reply = await http.post(
            "/webrtc",
            content=pc.localDescription.sdp,
            headers={"Content-Type": "application/sdp"},
        )
    assert reply.status_code == 201, reply.text
    await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
    with anyio.fail_after(10):
        await opened.wait()
    return WebRtcClient(name, channel=channel, inbox=inbox)


@dataclass
class Harness:
    """A running in-process server with every transport, and a way to connect to each."""

    server: RosbridgeServer
    stack: AsyncExitStack
    stdio_client: PipeStream
    ssl_context: ssl.SSLContext | None = None

    def port(self, kind: str) -> int:
        return int(self.server.urls[kind].rsplit(":", 1)[1])

    async def connect(self, transport: str, name: str | None = None) -> Client:
        name = name or transport
        if transport == "memory":
            connection = await self.stack.enter_async_context(self.server.connect_memory())
            return MemoryClient(name, connection=connection)
        if transport == "ws":
            scheme = "wss" if self.ssl_context else "ws"
            # No client keepalive: websockets draws its ping payloads from the global
            # ``random``, and a ping sent from a server's thread while hypothesis draws
            # an example in the main thread (tests/fuzz) fails that test as a strategy
            # using ``random``. The server's own pings are unaffected and still answered.
            ws = await connect(
                f"{scheme}://127.0.0.1:{self.port('websocket')}",
                ssl=self.ssl_context,
                ping_interval=None,
            )
            self.stack.push_async_callback(ws.close)
            return WsClient(name, ws=ws)
        if transport == "tcp":
            stream: ByteStream = await anyio.connect_tcp(
                "127.0.0.1", self.port("tcp"), ssl_context=self.ssl_context
            )
            self.stack.push_async_callback(anyio.aclose_forcefully, stream)
            return StreamClient(name, stream=stream)
        if transport == "udp":
            sock = await anyio.create_connected_udp_socket("127.0.0.1", self.port("udp"))
            self.stack.push_async_callback(sock.aclose)
            with anyio.fail_after(10):
                prefix = await validate_udp(sock)
            return UdpClient(name, sock=sock, prefix=prefix)
        if transport == "stdio":
            return StreamClient(name, stream=self.stdio_client)
        if transport in ("webrtc", NATIVE_WEBRTC, REACTOR_WEBRTC):
            base = f"http://127.0.0.1:{self.port('websocket')}"
            return await connect_webrtc(base, self.stack, name)
        raise ValueError(transport)


@asynccontextmanager
async def running_server(
    config: ServerConfig | None = None, *, webrtc_stack: str = "aiortc", **server_kw: Any
) -> AsyncIterator[Harness]:
    """An in-process server with WebSocket, TCP, UDP and stdio (on pipes), all on free ports.

    With aiortc installed it answers WebRTC offers on the WebSocket port too
    (``HAS_AIORTC``) with ``webrtc_stack`` (``--webrtc-stack``), unless ``config``
    says otherwise.
    """
    to_server_r, to_server_w = os.pipe()
    from_server_r, from_server_w = os.pipe()
    config = replace(
        config or ServerConfig(),
        port=0,
        tcp_port=0,
        udp_port=0,
        stdio=True,
        stdio_fds=(to_server_r, from_server_w),
    )
    if HAS_AIORTC and config.webrtc is None:
        config = replace(config, webrtc=WebRtcOptions(stack=webrtc_stack))
    server = RosbridgeServer(config=config, **server_kw)
    pipe = PipeStream(to_server_w, from_server_r)
    async with AsyncExitStack() as stack, anyio.create_task_group() as tg:
        await tg.start(server.serve)
        harness = Harness(server, stack, pipe)
        try:
            yield harness
        finally:
            await stack.aclose()
            server.stop()
        # let the server end on its own; then close what the test did not
    for fd in (to_server_r, from_server_w):
        os.close(fd)
    await pipe.aclose()
