"""The HTTP API's transport: its paths on the WebSocket port, one pump per request.

The front end itself is ``rwt_http`` (sans-IO: routes, the session, the OpenAPI
document; docs/http.md). Here: the endpoint claims ``/openapi.json`` and
``/api/...`` (an ``HttpEndpoint``), reads the request (bounded, CORS, through
``endpoint``), checks the bearer token through the server's one entry check
(``FrontEndHost.entry``, ``AuthMode.BEARER``: the same tokens as WebRTC's and
MCP's), has the server admit the connection (``open_session``: ``--max-connections``, the host
shares, ``/connected_clients``) and runs the session with the connection pump
over the socket (``HttpChannel``): the request's body is its one frame, what the
session queues is written as it is (a whole response, or an event stream's head
and events), the writer's backpressure and the slow-consumer rule are the
pump's, as for every connection.

It is registered as ``frontends_registry.HTTP_API``;
``ServerConfig.http_options["http"] = None`` turns it off (``rwt serve --no-http-api``).
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

import anyio

from rwt_http import API_PREFIX, OPENAPI_PATH, HttpApiOptions, HttpSession, RouteError, parse_route
from rwt_http.wire import error_response, no_content
from rwt_protocol.runtime.inframes import FramerEvent, InFrame

from ..channel import PlainChannel
from ..frontends import AuthMode, FrontEnd
from ..pump import ConnectionPump, run_connection
from .endpoint import claims_path, open_request
from .version import installed_version

if TYPE_CHECKING:
    from collections.abc import Sequence

    from anyio.abc import ByteStream, TaskGroup

    from rwt_protocol.runtime.commands import CloseCode
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.outbox import OutFrame
    from rwt_protocol.runtime.request import SessionRequest

    from ..host import FrontEndHost

__all__ = ["API_PATHS", "HttpApiEndpoint", "HttpChannel", "http_api_endpoint"]

logger = logging.getLogger("rwt.http")

_METHODS = (b"GET", b"HEAD", b"POST", b"OPTIONS", b"PUT", b"PATCH", b"DELETE")
_ALLOW = b"GET, HEAD, POST, OPTIONS"
_CORS = [
    (b"Access-Control-Allow-Methods", _ALLOW),
    (b"Access-Control-Allow-Headers", b"Authorization, Content-Type"),
]
_READ_SIZE = 65536


class HttpChannel(PlainChannel):
    """One request's socket as a pump ``Channel``: the body in, the session's bytes out.

    ``receive`` gives the request's body once as the session's one frame, then reads
    (and drops) what else comes until the peer leaves (``anyio.EndOfStream``): an
    event stream's client that goes away is seen so.
    """

    transport = "http"
    awaits_peer_close = False

    def __init__(self, stream: ByteStream, body: bytes) -> None:
        self._stream = stream
        self._body: bytes | None = body

    async def receive(self) -> Sequence[FramerEvent]:
        """The body first, then nothing until the peer leaves (bytes after it are dropped)."""
        if self._body is not None:
            body, self._body = self._body, None
            return [InFrame(body)]
        try:
            await self._stream.receive(_READ_SIZE)
        except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            raise anyio.EndOfStream from None
        return []

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Write the frames' bytes as they are (the session made the HTTP)."""
        await self._stream.send(b"".join(frame.prefix + frame.data for frame in frames))

    async def close(self, code: CloseCode, reason: str) -> None:
        """End the response: close the socket (``Connection: close``)."""
        await self._stream.aclose()

    async def background(self, session: ServerSession) -> None:
        """Nothing to do."""


def _names_api(_method: bytes, after: bytes) -> bool:
    return True  # every path under /api/ is the API's


def _names_document(_method: bytes, after: bytes) -> bool:
    return after in (b" ", b"?")


class HttpApiEndpoint:
    """Answers the HTTP API's paths on the WebSocket port (an ``HttpEndpoint``; the module's text).

    Args:
        host: the server whose graph it serves and which admits its requests.
        options: the API's settings.
    """

    def __init__(self, host: FrontEndHost, options: HttpApiOptions) -> None:
        self.host = host
        self.options = options
        self.allowed_origins = host.settings.allowed_origins
        self.max_body = options.max_body_bytes or host.settings.max_message_size

    def bind(self, tg: TaskGroup | None) -> None:
        """Nothing to do: each request runs in its socket's task, admitted by the server."""

    @staticmethod
    def claims(head: bytes) -> bool | None:
        """Whether the request starting with ``head`` is the API's; None: too short."""
        api = claims_path(head, _METHODS, API_PREFIX, _names_api)
        if api is not False:
            return api
        return claims_path(head, _METHODS, OPENAPI_PATH, _names_document)

    async def serve(self, stream: ByteStream, head: bytes, peer: str) -> None:
        """Answer the one request on ``stream`` whose first bytes are ``head``.

        The caller bounds the time until the request is read (the handshake
        timeout); admitted, it runs as long as its session does.
        """
        opened = await open_request(
            stream,
            head,
            limit=self.max_body,
            too_large=f"the request's body is over {self.max_body} bytes",
            allowed_origins=self.allowed_origins,
            cors=_CORS,
        )
        if opened is None:
            return
        cors = tuple(opened.cors)
        method = opened.request.method.decode("latin-1")
        if method == "OPTIONS":
            await _send(stream, 204, "", (*cors, (b"Allow", _ALLOW)))
            return
        try:
            route = parse_route(method, opened.request.target.decode("latin-1"))
        except RouteError as exc:
            await _send(stream, exc.status, exc.text, cors)
            return
        refusal = self.host.entry.check(
            AuthMode.BEARER, peer, headers=opened.headers, now=time.monotonic()
        )
        if refusal is not None:
            await _send(stream, refusal.status, refusal.text, (*cors, _CHALLENGE))
            return
        channel = HttpChannel(stream, opened.body)
        pump = ConnectionPump(channel, self.host.flow, self.host.admission)

        def make(request: SessionRequest) -> HttpSession:
            return HttpSession(
                self.host.graph.port,
                request.client_id,
                route,
                headers=cors,
                config=request.rules,
                options=self.options,
                version=installed_version(),
                head_only=method == "HEAD",
                on_output=request.on_output,
                peer=request.peer,
                on_closed=request.on_closed,
                memory=request.memory,
            )

        frontend = FrontEnd("http", (), make)
        session = self.host.open_session(
            "http", peer, pump.wake, frontend=frontend, authenticated=True
        )
        if session is None:
            await _send(stream, 503, "too many connections", cors)
            return
        await run_connection(pump, session, f"route={route.kind.value} name={route.name}")


_CHALLENGE = (b"WWW-Authenticate", b"Bearer")


async def _send(
    stream: ByteStream, status: int, text: str, headers: Sequence[tuple[bytes, bytes]]
) -> None:
    """Answer a request refused before any session: ``{"error": text}`` (204: nothing)."""
    data = (
        no_content(tuple(headers))
        if status == 204
        else error_response(status, text, tuple(headers))
    )
    try:
        await stream.send(data)
    except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
        logger.debug("event=http_refused peer gone status=%d", status)


API_PATHS = (API_PREFIX, OPENAPI_PATH)
"""The paths the API answers on the WebSocket port: ``/api/...`` and its OpenAPI document."""


def http_api_endpoint(host: FrontEndHost, options: object) -> HttpApiEndpoint:
    """The HTTP API of ``host`` (``frontends_registry.HTTP_API``); other options: the defaults."""
    return HttpApiEndpoint(
        host, options if isinstance(options, HttpApiOptions) else HttpApiOptions()
    )
