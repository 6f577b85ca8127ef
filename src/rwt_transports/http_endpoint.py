"""What the HTTP endpoints on the WebSocket port share: claiming, reading, answering.

The WebSocket listener reads the start of a connection and offers it to each HTTP
endpoint (``/version``, WebRTC signalling, MCP) before the WebSocket handshake takes it
(docs/architecture.md). Each endpoint answers one request a connection with h11:
``open_request`` reads it (bounded), answers the malformed, oversized and
cross-origin ones itself, and ``reply`` sends a response and ends the connection.
A bearer token is read by ``bearer`` (``rwt_protocol.credentials``, the one parser)
and checked by the server's one entry check (``GraphServer.entry``).
"""

from __future__ import annotations

import contextlib
import fnmatch
from dataclasses import dataclass
from http import HTTPStatus
from typing import TYPE_CHECKING

import anyio
import h11

from rwt_protocol.credentials import bearer  # the one reading of a bearer token

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from anyio.abc import ByteStream

__all__ = [
    "HttpRequest",
    "bearer",
    "claims_path",
    "cors_headers",
    "open_request",
    "read_request",
    "reply",
]

Headers = list[tuple[bytes, bytes]]

_READ_SIZE = 65536


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

    Answers itself: 400 to what h11 cannot read, 413 (``too_large``) to a body over
    ``limit`` bytes, 403 to an origin ``allowed_origins`` refuses; None also when the
    peer left first.
    """
    conn = h11.Connection(h11.SERVER)
    conn.receive_data(head)
    try:
        request, body = await read_request(conn, stream, limit)
    except h11.RemoteProtocolError as exc:
        await reply(conn, stream, exc.error_status_hint, f"bad request: {exc}", [])
        return None
    if request is None:
        return None
    if body is None:
        await reply(conn, stream, 413, too_large, [])
        return None
    headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in request.headers}
    origin = headers.get("origin")
    allowed = cors_headers(origin, allowed_origins, cors)
    if allowed is None:
        await reply(conn, stream, 403, f"origin {origin} is not allowed", [])
        return None
    return HttpRequest(conn, request, body, headers, allowed)


async def read_request(
    conn: h11.Connection, stream: ByteStream, limit: int
) -> tuple[h11.Request | None, bytes | None]:
    """The request and its body; (None, b"") if the peer left first (h11 bounds the head).

    The body is None when it is over ``limit`` bytes (the rest is not read).

    Raises:
        h11.RemoteProtocolError: not HTTP/1.1 h11 can read.
    """
    request: h11.Request | None = None
    body = bytearray()
    while True:
        event = conn.next_event()
        if event is h11.NEED_DATA:
            try:
                data = await stream.receive(_READ_SIZE)
            except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
                data = b""
            conn.receive_data(data)
        elif isinstance(event, h11.Request):
            request = event
        elif isinstance(event, h11.Data):
            body += event.data
            if len(body) > limit:
                return request, None
        elif isinstance(event, h11.EndOfMessage):
            return request, bytes(body)
        else:  # ConnectionClosed, PAUSED
            return None, b""


async def reply(
    conn: h11.Connection,
    stream: ByteStream,
    status: int,
    text: str,
    headers: list[tuple[bytes, bytes]],
    kind: str = "text/plain; charset=utf-8",
) -> None:
    """Send one response and let the connection end (``Connection: close``; also ``mcp_http``'s)."""
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
