"""What the HTTP endpoints on the WebSocket port share: claiming, reading, answering.

The WebSocket listener reads the start of a connection and offers it to each HTTP
endpoint (``/version``, WebRTC signalling, MCP, the HTTP API) before the WebSocket
handshake takes it (docs/architecture.md). Each endpoint answers one request a
connection with h11: ``open_request``, the one reader, reads it (bounded before the
request is admitted by the socket's ``pending`` record, and by the work it costs,
D58), answers the malformed, oversized, refused and cross-origin ones itself, and
``reply`` sends a response and ends the connection.
A bearer token is read by ``bearer`` (``rwt_protocol.credentials``, the one parser)
and checked by the server's one entry check (``FrontEndHost.entry``).
"""

from __future__ import annotations

import contextlib
import fnmatch
from dataclasses import dataclass
from enum import Enum
from http import HTTPStatus
from typing import TYPE_CHECKING, Protocol

import anyio
import h11

from rwt_protocol.credentials import bearer  # the one reading of a bearer token

from ..admission.pending import RETRY_AFTER_S, PendingRefusal, current_socket
from ..pump import READ_SLICE_BYTES

if TYPE_CHECKING:
    from collections.abc import AsyncIterator, Callable, Sequence

    from anyio.abc import ByteStream, TaskGroup

    from ..admission.pending import PendingSocket

__all__ = [
    "MAX_HEAD_BYTES",
    "READ_SLICE_EVENTS",
    "REFUSED_DRAIN_S",
    "HttpEndpoint",
    "HttpRequest",
    "bearer",
    "claims_path",
    "cors_headers",
    "drain_refused",
    "open_request",
    "reply",
]

Headers = list[tuple[bytes, bytes]]

_READ_SIZE = 65536

MAX_HEAD_BYTES = 64 * 1024
"""The longest request head read on the WebSocket port (its request line and headers),
bytes: tornado's default, rosbridge_suite's server's; longer gets 431 (D58)."""


class HttpEndpoint(Protocol):
    """An HTTP front end on the WebSocket port (``/version``, WebRTC, MCP, the HTTP API).

    It claims requests by their first bytes and answers them; the server makes it
    from its registry entry (``frontends_registry.HttpFrontEnd``) and binds it while serving.
    """

    def claims(self, head: bytes) -> bool | None:
        """Whether the request starting with ``head`` is this endpoint's; None: too short."""

    async def serve(self, stream: ByteStream, head: bytes, peer: str) -> None:
        """Answer the request on ``stream`` whose first bytes are ``head``."""

    def bind(self, tg: TaskGroup | None) -> None:
        """Run what outlives a request in ``tg`` (the server's connections).

        None: the server is stopping (or stopped): take nothing new, and free
        what has not started.
        """


def claims_path(
    head: bytes,
    methods: Sequence[bytes],
    path: str,
    accepts: Callable[[bytes, bytes], bool],
) -> bool | None:
    """Whether the request starting with ``head`` is one of ``methods`` on ``path``.

    Args:
        head: the first bytes the client sent (a request line's start).
        methods: the HTTP methods the endpoint answers, such as ``b"POST"``.
        path: the endpoint's path, such as ``/webrtc``.
        accepts: ``accepts(method, byte)`` says whether the byte after the path
            (``b" "``, ``b"/"``, ``b"?"``...) still names the endpoint.

    Returns:
        True or False; None while ``head`` is too short to tell.
    """
    target = path.encode()
    for method in methods:
        prefix = method + b" " + target
        if len(head) <= len(prefix):
            if prefix.startswith(head):
                return None
            continue
        if head.startswith(prefix):
            return accepts(method, head[len(prefix) : len(prefix) + 1])
    return False


def cors_headers(origin: str | None, allowed: Sequence[str], base: Headers) -> Headers | None:
    """The CORS headers for a request from ``origin``; None if ``allowed`` refuses it.

    Args:
        origin: the request's ``Origin`` header, if any (none: no CORS headers).
        allowed: ``--allowed-origins``' glob patterns; empty allows every origin.
        base: the endpoint's own ``Access-Control-*`` headers.
    """
    if origin is None:
        return []
    if allowed and not any(fnmatch.fnmatchcase(origin, p) for p in allowed):
        return None
    return [(b"Access-Control-Allow-Origin", origin.encode("latin-1")), *base]


@dataclass(frozen=True, slots=True)
class HttpRequest:
    """A request read whole: its connection, head, body, headers and CORS headers."""

    conn: h11.Connection
    request: h11.Request
    body: bytes
    headers: dict[str, str]  # lower-case names
    cors: Headers


async def open_request(
    stream: ByteStream,
    head: bytes,
    *,
    limit: int,
    too_large: str,
    allowed_origins: Sequence[str],
    cors: Headers,
) -> HttpRequest | None:
    """Read the request whose first bytes are ``head``, or answer it and return None.

    The one reader of every HTTP endpoint on the WebSocket port (docs/limits.md, D58):
    what it keeps of the request before the server admits it is charged to the
    socket's ``admission.pending.PendingSocket`` (the budgets and its host's share), and it
    yields to the event loop by the work it did (``READ_SLICE_EVENTS``,
    ``READ_SLICE_BYTES``), not by the reads, so a body of 1-byte chunks costs the
    other clients no more than its bytes would. Answers itself: 400 to what h11
    cannot read, 413 (``too_large``) to a body over ``limit`` bytes (a declared one
    before a byte of it is read), 429 or 503 with ``Retry-After`` to what the pending
    requests' bounds refuse, 403 to an origin ``allowed_origins`` refuses; None also
    when the peer left first. A refused request's socket is read (and what comes
    dropped) for up to ``REFUSED_DRAIN_S`` after the answer, so that a client still
    sending its body reads the answer instead of a reset.
    """
    conn = h11.Connection(h11.SERVER, max_incomplete_event_size=MAX_HEAD_BYTES)
    conn.receive_data(head)
    reader = _RequestReader(conn, stream, limit, current_socket())
    try:
        read = await reader.read(len(head))
    except h11.RemoteProtocolError as exc:
        await _refuse(reader, exc.error_status_hint, f"bad request: {exc}", [])
        return None
    if read is None:
        return None
    if isinstance(read, PendingRefusal):
        retry = [(b"Retry-After", str(RETRY_AFTER_S).encode())]
        await _refuse(reader, read.status, read.text, retry)
        return None
    if isinstance(read, _Step):  # TOO_LARGE: the others stay inside ``read``
        await _refuse(reader, 413, too_large, [])
        return None
    assert reader.request is not None  # read whole
    headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in reader.request.headers}
    origin = headers.get("origin")
    allowed = cors_headers(origin, allowed_origins, cors)
    if allowed is None:  # read whole: nothing to drop
        await reply(conn, stream, 403, f"origin {origin} is not allowed", [])
        return None
    return HttpRequest(conn, reader.request, read, headers, allowed)


READ_SLICE_EVENTS = 64
"""h11 events (a chunk of a chunked body is one, some 12 us of h11's work) the reader
handles before it lets the event loop turn, however few reads brought them (D58)."""

REFUSED_DRAIN_S = 2.0
"""Seconds a refused request's socket is still read, what comes dropped, after its answer."""


class _Step(Enum):
    """Where a slice of the reader's work left the request (besides its outcome)."""

    NEED_DATA = "need data"  # h11 needs more bytes
    SLICE_DONE = "slice done"  # the slice's work is done: the others' turn
    TOO_LARGE = "too large"  # a body over the endpoint's limit: 413


class _Body:
    """A body as it arrives: its pieces as h11 gave them, small ones joined.

    Not one growing buffer: a bytearray grown to 10 MiB is reallocated again and
    again, and the blocks it leaves behind, between other sockets' blocks, were
    freed but not given back to the system.
    """

    __slots__ = ("_parts", "_size", "_small")

    def __init__(self) -> None:
        self._parts: list[bytes] = []
        self._small = bytearray()  # 1-byte chunks and the like, joined up to _PART
        self._size = 0

    def __len__(self) -> int:
        return self._size

    def add(self, data: bytes) -> None:
        """Keep ``data`` (a piece of the body)."""
        self._size += len(data)
        if len(data) >= _PART // 16 and not self._small:
            self._parts.append(data)
            return
        self._small += data
        if len(self._small) >= _PART:
            self._parts.append(bytes(self._small))
            self._small = bytearray()

    def take(self) -> bytes:
        """The whole body; nothing is kept here after."""
        parts, self._parts = self._parts, []
        body = b"".join([*parts, self._small])
        self._small = bytearray()
        self._size = 0
        return body


_PART = 65536  # bytes of small pieces joined into one (one read's worth)


class _RequestReader:
    """One request read by h11, charged to its socket, in slices of work (``open_request``).

    Attributes:
        request: the request's head once read, else None.
    """

    def __init__(
        self,
        conn: h11.Connection,
        stream: ByteStream,
        limit: int,
        socket: PendingSocket | None,
    ) -> None:
        self.conn = conn
        self.stream = stream
        self.limit = limit
        self.socket = socket
        self.request: h11.Request | None = None
        self._body = _Body()
        self._declared = 0  # its Content-Length, charged before the body is read
        self._received = 0  # bytes read until the head was whole (h11 keeps them)
        self._unparsed = 0  # bytes of the latest read, given to h11 (an upper bound)
        self._continued = False

    async def read(self, first: int) -> bytes | PendingRefusal | _Step | None:
        """The body, ``_Step.TOO_LARGE``, a refusal, or None: the peer left first.

        ``first``: the bytes given to h11 already (the head's first read).

        Raises:
            h11.RemoteProtocolError: not HTTP/1.1 h11 can read (h11 bounds the head).
        """
        data_size = first
        while True:
            self._received += 0 if self.request is not None else data_size
            self._unparsed = data_size
            refusal = self._charge()
            if refusal is not None:
                return refusal
            done = await self._parse()
            if done is not _Step.NEED_DATA:
                return done
            if self.request is not None and not self._continued:
                await self._send_continue()
            try:
                data = await self.stream.receive(_READ_SIZE)
            except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
                data = b""
            self.conn.receive_data(data)
            data_size = len(data)

    def _charge(self) -> PendingRefusal | None:
        """Charge what is kept now: the head so far, or the body and the latest read.

        The body as declared (``Content-Length``) or as read, whichever is more, and
        the bytes of the latest read, which h11 holds until they are parsed.
        """
        if self.socket is None:
            return None
        if self.request is None:
            return self.socket.hold(self._received)
        return self.socket.hold(max(self._declared, len(self._body)) + self._unparsed)

    async def _parse(self) -> bytes | PendingRefusal | _Step | None:
        """Handle what h11 has, a slice at a time in the host's turn.

        Returns ``_Step.NEED_DATA`` when h11 needs more bytes, else ``read``'s outcome.
        """
        turn = self.socket.turn if self.socket is not None else _no_turn
        while True:
            async with turn():
                done = self._slice()
            if done is not _Step.SLICE_DONE:
                return done
            await anyio.lowlevel.checkpoint()  # the others' turn: the slice is done

    def _slice(self) -> bytes | PendingRefusal | _Step | None:
        """At most ``READ_SLICE_EVENTS`` events or ``READ_SLICE_BYTES`` bytes of body."""
        events = size = 0
        conn, body = self.conn, self._body
        while events < READ_SLICE_EVENTS and size < READ_SLICE_BYTES:
            event = conn.next_event()
            if event is h11.NEED_DATA:
                return _Step.NEED_DATA
            events += 1
            if isinstance(event, h11.Data):
                body.add(event.data)
                size += len(event.data)
                if len(body) > self.limit:
                    return _Step.TOO_LARGE
            elif isinstance(event, h11.Request):
                refusal = self._head(event)
                if refusal is not None:
                    return refusal
            elif isinstance(event, h11.EndOfMessage):
                return self._whole()
            else:  # ConnectionClosed, PAUSED
                return None
        return _Step.SLICE_DONE

    def _head(self, request: h11.Request) -> PendingRefusal | _Step | None:
        """The head is whole: count the request as its host's, charge its declared body."""
        self.request = request
        refusal = self.socket.enter() if self.socket is not None else None
        if refusal is not None:
            return refusal
        length = _content_length(request)
        if length > self.limit:
            return _Step.TOO_LARGE
        self._declared = length
        return self._charge()

    def _whole(self) -> bytes:
        """The body, read whole; what else is charged for it is given back."""
        body = self._body.take()
        self._declared = 0
        if self.socket is not None:
            self.socket.hold(len(body))
        return body

    async def _send_continue(self) -> None:
        """Tell a client waiting for it (``Expect: 100-continue``) to send its body."""
        self._continued = True
        if not self.conn.they_are_waiting_for_100_continue:
            return
        data = self.conn.send(h11.InformationalResponse(status_code=100, headers=[]))
        with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            await self.stream.send(data or b"")


@contextlib.asynccontextmanager
async def _no_turn() -> AsyncIterator[None]:
    yield


def _content_length(request: h11.Request) -> int:
    """The request's declared ``Content-Length`` (h11 checked it), 0 without one."""
    for name, value in request.headers:
        if name == b"content-length":
            return int(value)
    return 0


async def _refuse(reader: _RequestReader, status: int, text: str, headers: Headers) -> None:
    """Answer a request refused before it was read whole, then drop what else comes.

    Nothing is charged for it from here on. The socket is read for up to
    ``REFUSED_DRAIN_S`` (until the peer's end) after the answer and its end of the
    stream, so that a client still sending its body sees the answer, not a reset.
    """
    if reader.socket is not None:
        reader.socket.refused()
    conn, stream = reader.conn, reader.stream
    if reader.request is None and conn.their_state is not h11.ERROR:
        await _send_raw(stream, status, text, headers)  # no head yet: h11 cannot answer
    else:
        await reply(conn, stream, status, text, headers)
    await drain_refused(stream, reader.socket)


async def drain_refused(stream: ByteStream, socket: PendingSocket | None) -> None:
    """After the answer to a refused request: end our side, drop what the peer still sends.

    For up to ``REFUSED_DRAIN_S``, or until the peer's end: closing a socket with
    bytes unread makes the kernel reset the connection, and a client still sending
    its request (a body, a head) would read the reset instead of the answer. Each
    read waits for the turn of ``socket``'s host (``PendingSocket.wait_turn``), so a
    host's refused sockets cost the others one read a turn of the event loop.
    """
    with contextlib.suppress(Exception):  # TLS has no half-close; a peer gone is done
        await stream.send_eof()
    with anyio.move_on_after(REFUSED_DRAIN_S):
        with contextlib.suppress(anyio.EndOfStream, anyio.BrokenResourceError, OSError):
            while True:
                if socket is not None:
                    await socket.wait_turn()
                await stream.receive(_READ_SIZE)


async def reply(
    conn: h11.Connection,
    stream: ByteStream,
    status: int,
    text: str,
    headers: list[tuple[bytes, bytes]],
    kind: str = "text/plain; charset=utf-8",
) -> None:
    """Send one response and let the connection end (``Connection: close``; also ``mcp``'s)."""
    body = (text + "\n" if text and kind.startswith("text/") else text).encode()
    fields = [*headers, (b"Connection", b"close")]
    if status != 204:  # no content: no type, no length (RFC 9110 8.6)
        fields += [(b"Content-Type", kind.encode()), (b"Content-Length", str(len(body)).encode())]
    with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
        try:
            reason = HTTPStatus(status).phrase.encode()
            data = conn.send(h11.Response(status_code=status, headers=fields, reason=reason))
            if body:
                data = (data or b"") + (conn.send(h11.Data(data=body)) or b"")
            data = (data or b"") + (conn.send(h11.EndOfMessage()) or b"")
        except h11.LocalProtocolError:  # h11 is in a state where it cannot answer
            return
        await stream.send(data)


async def _send_raw(stream: ByteStream, status: int, text: str, headers: Headers) -> None:
    """``reply``'s answer, for a request whose head h11 has not read (it cannot answer)."""
    body = (text + "\n").encode()
    fields = [
        *headers,
        (b"Connection", b"close"),
        (b"Content-Type", b"text/plain; charset=utf-8"),
        (b"Content-Length", str(len(body)).encode()),
    ]
    status_line = f"HTTP/1.1 {status} {HTTPStatus(status).phrase}".encode()
    data = b"\r\n".join([status_line, *(name + b": " + value for name, value in fields)])
    with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
        await stream.send(data + b"\r\n\r\n" + body)
