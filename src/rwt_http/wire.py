"""The bytes the HTTP API sends: whole responses, an event stream's head, its events.

HTTP/1.1 (RFC 9112): every response ends the connection (``Connection: close``),
one request a connection as the server's other HTTP endpoints; an event stream
has no length and runs until either side closes (Server-Sent Events, WHATWG HTML
9.2: ``text/event-stream``, an event is ``event:`` and ``data:`` lines and a blank
line).
"""

from __future__ import annotations

from http import HTTPStatus

from rwt_protocol.codecs.json import encode_json

__all__ = [
    "Headers",
    "error_response",
    "event",
    "json_response",
    "no_content",
    "not_modified",
    "response",
    "response_head",
    "stream_head",
]

Headers = tuple[tuple[bytes, bytes], ...]

_COMMON = (
    (b"Cache-Control", b"no-cache"),
    (b"X-Content-Type-Options", b"nosniff"),
    (b"Connection", b"close"),
)


def _head(status: int, fields: Headers) -> bytes:
    reason = HTTPStatus(status).phrase
    lines = [f"HTTP/1.1 {status} {reason}".encode()]
    lines += [name + b": " + value for name, value in (*fields, *_COMMON)]
    return b"\r\n".join(lines) + b"\r\n\r\n"


def response(
    status: int, body: bytes, kind: str, headers: Headers = (), *, head_only: bool = False
) -> bytes:
    """A whole response: status line, headers (``headers`` first), and ``body``.

    ``head_only``: the answer to a HEAD request (the length, no body).
    """
    fields = (
        *headers,
        (b"Content-Type", kind.encode()),
        (b"Content-Length", str(len(body)).encode()),
    )
    return _head(status, fields) + (b"" if head_only else body)


def response_head(status: int, kind: str, length: int, headers: Headers = ()) -> bytes:
    """The head of a response whose ``length`` bytes of body go as a frame of their own.

    A body many responses share (the OpenAPI document) is so sent without a copy.
    """
    fields = (*headers, (b"Content-Type", kind.encode()), (b"Content-Length", str(length).encode()))
    return _head(status, fields)


def not_modified(headers: Headers = ()) -> bytes:
    """304: the client's copy (its ``If-None-Match``) is current; a head alone (RFC 9110 15.4.5)."""
    return _head(304, headers)


def json_response(
    status: int, value: object, headers: Headers = (), *, head_only: bool = False
) -> bytes:
    """A response whose body is ``value`` as JSON (bytes as base64, D10)."""
    return response(status, encode_json(value), "application/json", headers, head_only=head_only)


def error_response(status: int, text: str, headers: Headers = ()) -> bytes:
    """A JSON error: ``{"error": text}`` with ``status``."""
    return json_response(status, {"error": text}, headers)


def no_content(headers: Headers = ()) -> bytes:
    """204: a head alone (no type, no length, RFC 9110 15.3.5)."""
    return _head(204, headers)


def stream_head(headers: Headers = ()) -> bytes:
    """The head of an event stream (200, ``text/event-stream``, no length)."""
    return _head(200, (*headers, (b"Content-Type", b"text/event-stream")))


def event(data: bytes, name: str | None = None) -> bytes:
    """One Server-Sent Event: ``data`` (JSON: one line) under ``name`` (None: ``message``)."""
    if name is None:
        return b"data: " + data + b"\n\n"
    return b"event: " + name.encode() + b"\ndata: " + data + b"\n\n"
