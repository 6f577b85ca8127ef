"""WebSocket transport: websockets' sans-IO protocol driven from anyio streams.

Why this shape (issue 2): websockets' ``ServerProtocol`` does the RFC 6455
parsing and framing without I/O, so one anyio task per connection reads bytes
into it and one writer task owns every write. That gives us what the protocol
needs and the asyncio server hides: a single writer per connection draining the
session's bounded outbox (D24), frames written without a per-subscriber await
in the publish path, the same code over plain TCP or TLS streams, and anyio's
structured cancellation for shutdown.

Text frames carry JSON, binary frames CBOR (D27). permessage-deflate is off
unless enabled (D30: Node's ``ws`` offers it; we decline). Incoming messages are
limited to ``max_message_size`` bytes (10 MiB default, D24/D30); a larger one
closes the connection with code 1009 (as rosbridge's tornado does, REF §1.1).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import anyio
from anyio.abc import ByteStream
from websockets.datastructures import Headers
from websockets.exceptions import InvalidState
from websockets.extensions.base import ServerExtensionFactory
from websockets.extensions.permessage_deflate import ServerPerMessageDeflateFactory
from websockets.frames import Frame, Opcode
from websockets.http11 import Request
from websockets.protocol import State
from websockets.server import ServerProtocol

from rwt_protocol.session import CloseConnection, Session

__all__ = ["WebSocketOptions", "serve_websocket_connection"]

logger = logging.getLogger("rwt.websocket")

MiB = 1024 * 1024
_READ_SIZE = 65536
_HANDSHAKE_LIMIT_S = 10.0


@dataclass(frozen=True, slots=True)
class WebSocketOptions:
    """WebSocket settings of a listener.

    Attributes:
        max_message_size: largest incoming message in bytes (``--max-message-size``).
        compression: offer permessage-deflate (``--websocket-compression``).
        url_path: the only path accepted, or None for any path.
    """

    max_message_size: int = 10 * MiB
    compression: bool = False
    url_path: str | None = None


SessionFactory = Callable[[str, Callable[[], None]], Session]
"""Makes the session of a new connection from (peer address, wake-up callback)."""


class _Connection:
    """One WebSocket connection: protocol state, session and the writer's wake-up."""

    def __init__(self, stream: ByteStream, protocol: ServerProtocol, limit: int) -> None:
        self.stream = stream
        self.protocol = protocol
        self.limit = limit
        self.wake = anyio.Event()
        self.parts: list[bytes] = []
        self.size = 0
        self.binary = False

    def signal(self) -> None:
        self.wake.set()

    async def flush(self) -> bool:
        """Write what the protocol has queued; return False once the stream must close."""
        for data in self.protocol.data_to_send():
            if data:
                await self.stream.send(data)
            else:
                return False
        return True

    def assemble(self, frame: Frame) -> bytes | None:
        """Collect fragmented data frames; return a whole message when complete."""
        if frame.opcode in (Opcode.TEXT, Opcode.BINARY):
            self.parts, self.size = [], 0
            self.binary = frame.opcode is Opcode.BINARY
        elif frame.opcode is not Opcode.CONT:
            return None
        self.parts.append(bytes(frame.data))
        self.size += len(frame.data)
        if self.size > self.limit:
            self.parts, self.size = [], 0
            self.protocol.fail(1009, "message too big")
            return None
        if not frame.fin:
            return None
        data = b"".join(self.parts)
        self.parts, self.size = [], 0
        return data


def _make_protocol(options: WebSocketOptions) -> ServerProtocol:
    extensions: list[ServerExtensionFactory] | None = None
    if options.compression:
        extensions = [ServerPerMessageDeflateFactory()]
    return ServerProtocol(max_size=options.max_message_size, extensions=extensions)


async def _handshake(conn: _Connection, options: WebSocketOptions) -> Request | None:
    protocol = conn.protocol
    with anyio.move_on_after(_HANDSHAKE_LIMIT_S):
        while True:
            try:
                data = await conn.stream.receive(_READ_SIZE)
            except (anyio.EndOfStream, anyio.BrokenResourceError):
                return None
            protocol.receive_data(data)
            for event in protocol.events_received():
                if isinstance(event, Request):
                    return event
            if protocol.state is not State.CONNECTING:
                return None
    return None


def _respond(conn: _Connection, request: Request, options: WebSocketOptions) -> None:
    protocol = conn.protocol
    path = request.path.split("?", 1)[0]
    if options.url_path is not None and path != options.url_path:
        response = protocol.reject(404, f"no rosbridge endpoint at {path}\n")
    else:
        response = protocol.accept(request)
    protocol.send_response(response)


async def serve_websocket_connection(
    stream: ByteStream, peer: str, make_session: SessionFactory, options: WebSocketOptions
) -> None:
    """Run one WebSocket connection to its end.

    Args:
        stream: the connected byte stream (TCP, or TLS over TCP).
        peer: the peer's address, for logs and the client id.
        make_session: builds the protocol session once the handshake succeeded.
        options: WebSocket settings.

    Never raises for what the peer does; the stream is closed on return.
    """
    conn = _Connection(stream, _make_protocol(options), options.max_message_size)
    async with stream:
        request = await _handshake(conn, options)
        if request is None:
            return
        _respond(conn, request, options)
        if not await conn.flush() or conn.protocol.state is not State.OPEN:
            return
        session = make_session(peer, conn.signal)
        logger.info("connect %s (%s)", session.client_id, _agent(request.headers))
        try:
            async with anyio.create_task_group() as tg:
                tg.start_soon(_writer, conn, session, tg.cancel_scope)
                await _reader(conn, session)
                tg.cancel_scope.cancel()
        finally:
            session.close()
            logger.info("disconnect %s", session.client_id)


async def _reader(conn: _Connection, session: Session) -> None:
    protocol = conn.protocol
    while protocol.state in (State.OPEN, State.CLOSING):
        try:
            data = await conn.stream.receive(_READ_SIZE)
        except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
            protocol.receive_eof()
            conn.signal()
            return
        protocol.receive_data(data)
        for event in protocol.events_received():
            if not isinstance(event, Frame):
                continue
            message = conn.assemble(event)
            if message is None:
                continue
            session.receive_frame(message, anyio.current_time(), binary=conn.binary)
        conn.signal()


async def _writer(conn: _Connection, session: Session, scope: anyio.CancelScope) -> None:
    protocol = conn.protocol
    try:
        while True:
            deadline = session.get_timer()
            delay = None if deadline is None else max(0.0, deadline - anyio.current_time())
            with anyio.move_on_after(delay):
                await conn.wake.wait()
            conn.wake = anyio.Event()
            session.handle_timer(anyio.current_time())
            _frames_to_protocol(protocol, session)
            if not await conn.flush() or protocol.state is State.CLOSED:
                scope.cancel()
                return
    except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
        scope.cancel()


def _frames_to_protocol(protocol: ServerProtocol, session: Session) -> None:
    try:
        for frame in session.frames_to_send():
            if frame.binary:
                protocol.send_binary(frame.data)
            else:
                protocol.send_text(frame.data)
        for command in session.commands_to_run():
            if isinstance(command, CloseConnection):
                protocol.send_close(command.code, command.reason)
    except InvalidState:
        pass  # closing: frames queued after the close frame are discarded


def _agent(headers: Headers) -> str:
    return headers.get("User-Agent", "unknown agent")
