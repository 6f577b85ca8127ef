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
from collections import Counter
from typing import TYPE_CHECKING

import anyio

from rwt_http import (
    API_PREFIX,
    OPENAPI_PATH,
    HttpApiOptions,
    HttpSession,
    Route,
    RouteError,
    RouteKind,
    StandingOffers,
    parse_route,
)
from rwt_http.wire import error_response, no_content
from rwt_protocol.runtime.inframes import FramerEvent, InFrame

from ..admission.shares import address_of
from ..channel import ChannelAbilities, PlainChannel
from ..direct import DirectWriter
from ..frontends import AuthMode, FrontEnd
from ..pump import ConnectionPump, run_connection
from ..sendqueue import stream_unsent_bytes
from ..writes import coalesce
from .documents import DocumentBuilds
from .endpoint import HttpRequest, claims_path, open_request
from .version import installed_version

if TYPE_CHECKING:
    from collections.abc import Sequence

    from anyio.abc import ByteStream, TaskGroup

    from rwt_protocol.runtime.commands import CloseCode
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.outbox import OutFrame
    from rwt_protocol.runtime.request import SessionRequest

    from ..host import FrontEndHost

__all__ = [
    "API_PATHS",
    "DOCUMENT_FETCHES_PER_HOST",
    "HttpApiEndpoint",
    "HttpChannel",
    "http_api_endpoint",
]

logger = logging.getLogger("rwt.http")

_METHODS = (b"GET", b"HEAD", b"POST", b"OPTIONS", b"PUT", b"PATCH", b"DELETE")
_ALLOW = b"GET, HEAD, POST, OPTIONS"
_CORS = [
    (b"Access-Control-Allow-Methods", _ALLOW),
    (b"Access-Control-Allow-Headers", b"Authorization, Content-Type"),
]
_READ_SIZE = 65536

DOCUMENT_FETCHES_PER_HOST = 2
"""Requests for ``/openapi.json`` one host has in flight at once (D59); the next gets 429."""

_STREAMS = (RouteKind.EVENTS, RouteKind.ACTION)
"""Routes answered with an event stream: under the host's share from the first (D59)."""


class HttpChannel(PlainChannel):
    """One request's socket as a pump ``Channel``: the body in, the session's bytes out.

    ``receive`` gives the request's body once as the session's one frame, then reads
    (and drops) what else comes until the peer leaves (``anyio.EndOfStream``): an
    event stream's client that goes away is seen so. Out, it writes as a TCP
    connection does (``tcp.StreamChannel``): small frames joined, a large one (a
    cached OpenAPI document) as it is, and on a plain socket from the publish path
    at once (``send_now``), so an event stream's message costs what a WebSocket
    subscriber's does (no writer task woken per message).
    """

    transport = "http"
    awaits_peer_close = False
    abilities = ChannelAbilities(unsent_bytes=True, send_now=True)
    """A socket: its send queue read, written at once; it is never read for input to hold."""

    def __init__(self, stream: ByteStream, body: bytes) -> None:
        self._stream = stream
        self._body: bytes | None = body
        self._direct = DirectWriter.for_stream(stream)

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
        """Write the frames' bytes as they are (the session made the HTTP), few writes."""
        for data in _writes(frames):
            await self._stream.send(data)

    def unsent_bytes(self) -> int | None:
        """Bytes the socket's kernel still holds for the peer (sendqueue.py)."""
        return stream_unsent_bytes(self._stream)

    def can_send_now(self) -> bool:
        """Whether ``send_now`` may write at once: a plain socket, nothing buffered."""
        return self._direct is not None and self._direct.ready

    def send_now(self, frames: Sequence[OutFrame]) -> None:
        """Write the frames without awaiting; call only when ``can_send_now`` is True.

        Raises:
            RuntimeError: not a plain socket, or the transport started closing.
        """
        if self._direct is None:
            raise RuntimeError("not a plain socket: send through the writer")
        for data in _writes(frames):
            self._direct.write(data)

    async def close(self, code: CloseCode, reason: str) -> None:
        """End the response: close the socket (``Connection: close``)."""
        await self._stream.aclose()

    async def background(self, session: ServerSession) -> None:
        """Nothing to do."""


def _writes(frames: Sequence[OutFrame]) -> list[bytes]:
    """The writes of ``frames``: small ones joined, a large payload not copied (``coalesce``)."""
    return coalesce((frame.prefix, frame.data, b"") for frame in frames)


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
        self.documents = DocumentBuilds(host.graph.port, installed_version())
        """The OpenAPI documents, made once per change of the graph and kept (D59)."""
        self.offers = StandingOffers(host.graph.port)
        """The registrations that keep a publish's ``qos`` past its request (D63)."""
        self._fetching: Counter[str] = Counter()  # hosts' requests for the document in flight

    def bind(self, tg: TaskGroup | None) -> None:
        """Make documents in ``tg``; None: the server is stopping.

        Each request runs in its socket's task, admitted by the server.
        """
        self.documents.bind(tg)

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
        if route.kind is not RouteKind.OPENAPI:
            await self._run(stream, opened, route, peer)
            return
        host = self.host.host_prefixes.host(address_of(peer))
        if self._fetching[host] >= DOCUMENT_FETCHES_PER_HOST:
            text = (
                f"this host fetches {OPENAPI_PATH} {DOCUMENT_FETCHES_PER_HOST} times at once "
                "already (DOCUMENT_FETCHES_PER_HOST): ask again when one is answered"
            )
            await _send(stream, 429, text, (*cors, (b"Retry-After", b"1")))
            return
        self._fetching[host] += 1
        try:
            await self._run(stream, opened, route, peer)
        finally:
            self._fetching[host] -= 1
            if self._fetching[host] <= 0:
                del self._fetching[host]

    async def _run(self, stream: ByteStream, opened: HttpRequest, route: Route, peer: str) -> None:
        """Have the server admit the request and run its session over ``stream``.

        An event stream counts under its host's share from the first (D59); a
        request the server refuses gets 503.
        """
        cors = tuple(opened.cors)
        method = opened.request.method.decode("latin-1")
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
                version=self.documents.cache.version,
                head_only=method == "HEAD",
                on_output=request.on_output,
                peer=request.peer,
                on_closed=request.on_closed,
                memory=request.memory,
                documents=self.documents,
                if_none_match=opened.headers.get("if-none-match"),
                offers=self.offers,
            )

        frontend = FrontEnd("http", (), make)
        session = self.host.open_session(
            "http",
            peer,
            pump.wake,
            frontend=frontend,
            authenticated=True,
            share_from_first=route.kind in _STREAMS,
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
