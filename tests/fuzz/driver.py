"""Drives one fuzz connection over any transport and checks the fuzz invariant.

The invariant (hardening): for the frames a client sends, the server answers only
with ``status`` frames or replies of the ops sent, or closes the connection
cleanly (a close frame with a code on WebSocket, EOF on TCP and stdio); it stays
up, and a bystander still gets a subscribe/publish round trip and a
``/rosapi/topics`` answer. ``Wire`` hides the transport; the in-process tests and
the B18 benchmark (``benchmarks/fuzz.py``) both drive connections through it.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

import anyio
import cbor2
from anyio.abc import ByteStream
from websockets.asyncio.client import ClientConnection
from websockets.exceptions import ConnectionClosed

from rwt_protocol.framing.streams import JsonStreamFramer
from rwt_protocol.runtime.inframes import FramingError, InFrame
from rwt_transports.memory import MemoryConnection
from tests.support.clients import validate_udp

Message = dict[str, Any]
REPLY_OPS = frozenset(
    {
        "status",  # errors and set_level answers
        "publish",  # what a subscription it made receives
        "png",  # the same, compression "png"
        "service_response",  # its call_service
        "call_service",  # a call to a service it advertised (it may call itself)
        "send_action_goal",  # a goal for an action it advertised
        "cancel_action_goal",
        "action_feedback",
        "action_result",
    }
)
STATUS_LEVELS = frozenset({"info", "warning", "error"})


_GONE = (anyio.BrokenResourceError, anyio.ClosedResourceError, ConnectionError)


class Violation(AssertionError):
    """The server broke the fuzz invariant."""


class Closed(Exception):
    """The server closed the connection cleanly (a close frame with a code, or EOF)."""


def _no_constants(name: str) -> None:
    raise Violation(f"the server wrote the non-JSON constant {name}")


def decode(data: bytes | str, binary: bool) -> Message:
    """One server frame as a message; a frame that is not a JSON/CBOR object is a violation."""
    try:
        if binary:
            value = cbor2.loads(data)
        else:
            text = data if isinstance(data, str) else data.decode("utf-8")
            value = json.loads(text, parse_constant=_no_constants)
    except (ValueError, cbor2.CBORDecodeError) as exc:
        raise Violation(
            f"the server sent an undecodable frame {bytes(data)[:200]!r}: {exc}"
        ) from exc
    if not isinstance(value, dict):
        raise Violation(f"the server sent a frame that is not an object: {value!r:.200}")
    return value


def check_reply(message: Message) -> None:
    """Only status frames or replies of ops a client can send (``REPLY_OPS``)."""
    op = message.get("op")
    if op not in REPLY_OPS:
        raise Violation(f"the server sent an op that answers nothing: {message!r:.300}")
    if op == "status" and (
        message.get("level") not in STATUS_LEVELS or not isinstance(message.get("msg"), str)
    ):
        raise Violation(f"malformed status: {message!r:.300}")


@dataclass
class Wire:
    """One client connection: raw frames out, decoded server messages in."""

    send: Callable[[bytes, bool], Awaitable[None]]
    next_frame: Callable[[], Awaitable[tuple[bytes | str, bool]]]
    finish: Callable[[], Awaitable[None]] | None = None
    handshake: Callable[[], Awaitable[None]] | None = None
    lossy: bool = False  # UDP: a datagram (the barrier too) may be lost, so it is resent
    parts: dict[object, dict[int, str]] = field(default_factory=dict)

    async def receive(self) -> Message:
        """The next whole message (server fragments reassembled); ``Closed`` at a clean close."""
        while True:
            data, binary = await self.next_frame()
            message = decode(data, binary)
            if message.get("op") != "fragment":
                return message
            try:
                parts = self.parts.setdefault(message["id"], {})
                parts[message["num"]] = message["data"]
                if len(parts) == message["total"]:
                    del self.parts[message["id"]]
                    return decode("".join(parts[i] for i in range(message["total"])), False)
            except (KeyError, TypeError) as exc:
                raise Violation(f"malformed fragment from the server: {message!r:.300}") from exc


async def exchange(
    wire: Wire, frames: list[tuple[bytes, bool]], tag: str, timeout_s: float
) -> bool:
    """Send ``frames`` and a barrier, check every answer until the barrier's; False if closed.

    Raises:
        Violation: an answer broke the invariant, or nothing came within ``timeout_s``.
    """
    barrier = {"op": "set_level", "level": "info", "id": tag}
    try:
        with anyio.fail_after(timeout_s):
            for data, binary in frames:
                await wire.send(data, binary)
            await wire.send(json.dumps(barrier).encode(), False)
            if wire.finish is not None:
                await wire.finish()
            try:
                async with anyio.create_task_group() as tg:
                    if wire.lossy:
                        tg.start_soon(_resend_every_second, wire, json.dumps(barrier).encode())
                    while True:
                        message = await wire.receive()
                        if message.get("op") == "status" and message.get("id") == tag:
                            tg.cancel_scope.cancel()
                            return True
                        check_reply(message)
            except BaseExceptionGroup as group:  # Closed or Violation, as without the group
                raise group.exceptions[0] from None
    except Closed:
        return False
    except TimeoutError as exc:
        raise Violation(f"no answer to the barrier within {timeout_s} s") from exc


async def _resend_every_second(wire: Wire, frame: bytes) -> None:
    """A UDP client's retry: the kernel drops datagrams when a busy reader falls behind."""
    while True:
        await anyio.sleep(1.0)
        await wire.send(frame, False)


# -- wires over the test clients (tests/support/clients.py) and plain sockets --


def memory_wire(connection: MemoryConnection) -> Wire:
    """A wire over an in-process connection."""

    async def next_frame() -> tuple[bytes, bool]:
        try:
            frame = await connection.receive_frame()
        except (anyio.EndOfStream, anyio.ClosedResourceError) as exc:
            raise Closed from exc
        return (frame.encode(), False) if isinstance(frame, str) else (frame, True)

    async def send(data: bytes, binary: bool) -> None:
        try:
            await connection.send_frame(data, binary=binary)
        except (anyio.BrokenResourceError, anyio.ClosedResourceError) as exc:
            raise Closed from exc

    return Wire(send, next_frame)


def ws_wire(ws: ClientConnection) -> Wire:
    """A wire over a WebSocket: text frames sent as bytes as they are (invalid UTF-8 too)."""

    async def next_frame() -> tuple[bytes | str, bool]:
        try:
            data = await ws.recv()
        except ConnectionClosed as exc:
            if exc.rcvd is None:
                raise Violation(
                    f"the WebSocket closed without a close frame (sent {exc.sent})"
                ) from exc
            raise Closed from exc
        return data, isinstance(data, bytes)

    async def send(data: bytes, binary: bool) -> None:
        try:
            await ws.send(data, text=not binary)
        except ConnectionClosed as exc:
            raise Closed from exc

    return Wire(send, next_frame)


def stream_wire(stream: ByteStream, *, eof_after: bool) -> Wire:
    """A wire over TCP or a stdio pipe pair: JSON text and CBOR items, told apart (D21)."""
    framer = JsonStreamFramer(1 << 26)
    pending: list[tuple[bytes, bool]] = []

    async def next_frame() -> tuple[bytes, bool]:
        while not pending:
            try:
                data = await stream.receive()
            except (anyio.EndOfStream, anyio.BrokenResourceError, ConnectionError) as exc:
                raise Closed from exc
            for event in framer.receive_data(data):
                if isinstance(event, FramingError):
                    raise Violation(f"the server wrote a bad frame: {event}")
                assert isinstance(event, InFrame)
                pending.append((event.data, event.binary))
        return pending.pop(0)

    async def send(data: bytes, binary: bool) -> None:
        try:
            await stream.send(data if binary else data + b"\n")
        except (anyio.BrokenResourceError, anyio.ClosedResourceError, ConnectionError) as exc:
            raise Closed from exc

    async def finish() -> None:
        # A frame may open a CBOR item or a string claiming megabytes: only the end
        # of the stream ends it, so the barrier's answer may never come; EOF ends it.
        with contextlib.suppress(*_GONE):
            await stream.send_eof()

    return Wire(send, next_frame, finish if eof_after else None)


def udp_wire(sock: Any) -> Wire:
    """A wire over a connected UDP socket: one datagram a frame, no close; every
    datagram carries the address-validation token (docs/limits.md, UDP)."""
    prefix = b""

    async def next_frame() -> tuple[bytes, bool]:
        data: bytes = await sock.receive()
        return data, data[:1] not in (b"{", b"[", b" ")

    async def send(data: bytes, binary: bool) -> None:
        await sock.send(prefix + data)

    async def handshake() -> None:
        nonlocal prefix
        with anyio.fail_after(10):
            prefix = await validate_udp(sock)

    return Wire(send, next_frame, handshake=handshake, lossy=True)


async def udp_handshake(wire: Wire) -> None:
    """The address validation a UDP client does before its session (docs/limits.md)."""
    assert wire.handshake is not None
    await wire.handshake()
