"""``GET /version`` on the WebSocket port: the protocol and server versions, and rwt's features.

rosbridge_server's version handler answers ``GET /version`` on its WebSocket port
with ``{"protocol": {"major", "minor", "patch"}, "server": "<version>"}`` as
``application/json`` (docs/reference-behaviour.md §13.4). rwt answers the same
fields, the protocol version from ``rwt_protocol.version.PROTOCOL_VERSION`` and the
server's from the installed distribution, plus ``rwt``: what this server offers
(``host.Features``), built from its configuration when the request comes. No
authentication, whatever ``--auth-secret-file`` says, as the reference's (D49):
the answer names no secret, topic, client, port or address.

One request a connection, read by h11 through ``endpoint`` (a body over
``MAX_BODY_BYTES`` is refused with 413; the caller's handshake timeout bounds the
time, and the socket holds a connection slot as any). ``GET`` and ``HEAD`` answer
200, ``OPTIONS`` 204 with ``Allow``, any other method 405. A browser's request is
answered with CORS headers when ``--allowed-origins`` allows its origin (any
origin when unset), 403 otherwise, as the other HTTP endpoints do.

``rwt serve --compat rosbridge-2.1`` imitates rosbridge_suite 2.1.0, which has no
such endpoint: there ``/version`` answers 404 to every method (``absent``), so a
client that reads it (``rwt conformance``) takes the server for the 2.1.0 era it
plays (D49).

It is an HTTP front end of the registry (``frontends_registry.VERSION``), the
smallest; the front ends it lists are the registry's as the server serves them.
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import json
import logging
from dataclasses import asdict
from functools import cache
from typing import TYPE_CHECKING

import anyio
import h11

from rwt_protocol.distribution import DISTRIBUTION
from rwt_protocol.server.compat import Compat
from rwt_protocol.version import PROTOCOL_VERSION

from .endpoint import claims_path, open_request, reply

if TYPE_CHECKING:
    from collections.abc import Callable

    from anyio.abc import ByteStream, TaskGroup

    from ..host import Features, FrontEndHost

__all__ = [
    "MAX_BODY_BYTES",
    "VERSION_PATH",
    "VersionEndpoint",
    "installed_version",
    "version_document",
    "version_endpoint",
]

logger = logging.getLogger("rwt.websocket")

VERSION_PATH = "/version"
"""Where the versions are answered (rosbridge_server's path, docs/reference-behaviour.md §13.4)."""

MAX_BODY_BYTES = 1024
"""Largest request body read (a ``GET /version`` has none): past it, 413."""

_METHODS = (b"GET", b"HEAD", b"OPTIONS", b"POST", b"PUT", b"PATCH", b"DELETE")
_ALLOW = b"GET, HEAD, OPTIONS"
_JSON = "application/json"
_CORS = [(b"Access-Control-Allow-Methods", _ALLOW)]


@cache
def installed_version() -> str:
    """The installed rwt's version (``rwt --version``); ``0+unknown`` from a source tree."""
    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        return "0+unknown"  # as rwt.__version__


def version_document(features: Features) -> dict[str, object]:
    """The JSON object ``GET /version`` answers, for a server offering ``features``.

    ``{"protocol": {"major": 2, "minor": 1, "patch": 0}, "server": "0.9.0",
    "rwt": {...}}``: the first two fields are rosbridge_server's
    (docs/reference-behaviour.md §13.4), ``rwt`` is ``Features`` as an object, with
    ``webrtc`` and ``mcp`` (whether those front ends are served, D49's fields) and
    ``safety`` (whether an envelope holds remote commands, docs/safety.md).
    """
    major, minor, patch = PROTOCOL_VERSION
    names = {each.name for each in features.frontends}
    return {
        "protocol": {"major": major, "minor": minor, "patch": patch},
        "server": installed_version(),
        "rwt": {
            "transports": list(features.transports),
            "encodings": list(features.encodings),
            "subprotocols": list(features.subprotocols),
            "webrtc": "webrtc" in names,
            "mcp": "mcp" in names,
            "auth": features.auth,
            "safety": features.safety,
            "frontends": [
                {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(each).items()}
                for each in features.frontends
            ],
        },
    }


def _names_version(_method: bytes, after: bytes) -> bool:
    """After ``/version``: the path ends (a space) or its query begins."""
    return after in (b" ", b"?")


class VersionEndpoint:
    """Answers ``/version`` on the WebSocket port (an ``HttpEndpoint``).

    Args:
        features: what the server offers, asked at each request (a front end
            added after the server was built shows).
        allowed_origins: fnmatch patterns of accepted ``Origin`` headers
            (``--allowed-origins``); empty: any origin.
        absent: why there is no version to tell (``--compat rosbridge-2.1``):
            every request is answered 404 with this text; None answers.
    """

    def __init__(
        self,
        features: Callable[[], Features],
        allowed_origins: tuple[str, ...] = (),
        absent: str | None = None,
    ) -> None:
        self.features = features
        self.allowed_origins = allowed_origins
        self.absent = absent

    def bind(self, tg: TaskGroup | None) -> None:
        """Nothing runs beyond a request."""

    @staticmethod
    def claims(head: bytes) -> bool | None:
        """Whether the request starting with ``head`` is for ``/version``; None: too short."""
        return claims_path(head, _METHODS, VERSION_PATH, _names_version)

    async def serve(self, stream: ByteStream, head: bytes, peer: str) -> None:
        """Answer the one request on ``stream`` whose first bytes are ``head``, then return.

        The caller bounds the time (the handshake timeout) and closes the stream.
        """
        opened = await open_request(
            stream,
            head,
            limit=MAX_BODY_BYTES,
            too_large=f"{VERSION_PATH} takes no body (at most {MAX_BODY_BYTES} bytes)",
            allowed_origins=self.allowed_origins,
            cors=_CORS,
        )
        if opened is None:
            return
        method = opened.request.method
        allow = [(b"Allow", _ALLOW)]
        if self.absent is not None:  # HEAD: no body (h11 refuses one)
            status = 404
            text = "" if method == b"HEAD" else self.absent
            await reply(opened.conn, stream, status, text, opened.cors)
        elif method in (b"GET", b"HEAD"):
            status = 200
            body = json.dumps(version_document(self.features())).encode()
            await _send_json(opened.conn, stream, body, opened.cors, head=method == b"HEAD")
        elif method == b"OPTIONS":
            status = 204
            await reply(opened.conn, stream, status, "", [*opened.cors, *allow])
        else:
            status = 405
            text = f"{VERSION_PATH} answers GET and HEAD only"
            await reply(opened.conn, stream, status, text, [*opened.cors, *allow])
        logger.debug(
            "event=version peer=%s method=%s status=%d", peer, method.decode("latin-1"), status
        )


async def _send_json(
    conn: h11.Connection,
    stream: ByteStream,
    body: bytes,
    headers: list[tuple[bytes, bytes]],
    *,
    head: bool,
) -> None:
    """Send ``body`` as JSON and end the connection; for HEAD its length and no body.

    ``endpoint.reply`` cannot answer HEAD: h11 refuses a body there.
    """
    fields = [
        *headers,
        (b"Content-Type", _JSON.encode()),
        (b"Content-Length", str(len(body)).encode()),
        (b"Cache-Control", b"no-cache"),
        (b"X-Content-Type-Options", b"nosniff"),
        (b"Connection", b"close"),
    ]
    with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
        data = conn.send(h11.Response(status_code=200, headers=fields, reason=b"OK")) or b""
        if not head:
            data += conn.send(h11.Data(data=body)) or b""
        data += conn.send(h11.EndOfMessage()) or b""
        await stream.send(data)


_NO_VERSION = "no /version: --compat rosbridge-2.1 plays rosbridge_suite 2.1.0, which has none"
"""``GET /version``'s 404 text in ``--compat rosbridge-2.1`` (``VersionEndpoint.absent``)."""


def version_endpoint(host: FrontEndHost, options: object) -> VersionEndpoint:
    """``GET /version`` of ``host`` (``frontends_registry.VERSION``; on whatever ``options``)."""
    absent = _NO_VERSION if host.settings.compat is Compat.ROSBRIDGE_2_1 else None
    return VersionEndpoint(host.features, host.settings.allowed_origins, absent)
