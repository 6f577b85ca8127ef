"""MCP over Streamable HTTP on the WebSocket port (``rwt serve --mcp``, docs/mcp.md).

An MCP client posts JSON-RPC to ``/mcp`` (``mcp_options.MCP_PATH``); the
WebSocket listener hands such a request here (``claims``). Each MCP session is
a session of the server's connection runtime, ``rwt_mcp.session.McpSession``
(``open_session`` with transport ``mcp``): it is admitted as every connection is
(``--max-connections``, the host's share, which for MCP sessions applies from the
first), runs under the same per-client limits, access rules and call book, ends
after ``--idle-timeout`` without a request in flight (the runtime's idle watch, as
every connection's; its pump runs its timers over a connection that carries no
frames), and the MCP tools (``rwt_mcp.tools``, the same as ``rwt mcp``'s) drive the
graph through it, with no rosbridge between them. The official MCP SDK
(2.x) answers the protocol (its ``StreamableHTTPServerTransport``, driven as an
ASGI app over the request's socket; h11 parses the request). A refused session
gets 503 and no MCP session.

Both revisions answer here (D52): a 2025-era client opens a session with
``initialize`` as above; a 2026-07-28 request (its ``MCP-Protocol-Version``
header a revision without the handshake) carries no session: it is one
``McpSession`` of its own, opened for the request and closed after its answer (a
``subscriptions/listen`` stream holds it while it runs), its timers driven without
a pump (``pump.drive_timers``), answered by the SDK's single-exchange entry. Its
rate caps are its host's (``MODERN_HOSTS_KEPT`` hosts kept). A goal it starts as a task keeps that
session open until the goal ends or the task expires (``rwt_mcp.tasks``); the
endpoint's ``TaskStore`` is shared by every session and request, so any of
them polls or cancels it.

Every socket a request holds is a connection slot (D40): a session holds
``SESSION_SLOTS`` (itself and its event stream, and one request), and a request
beyond them takes one more while it runs (``FrontEndHost.take_slot``), or gets
503; so requests in flight cannot run the server out of descriptors.

Safety (docs/mcp.md, "Safety"): with ``--auth-secret-file`` a new session needs
``Authorization: Bearer <token>``, a live token of ``/rwt/video_token`` (else
401; the server's one entry check, ``FrontEndHost.entry``, ``AuthMode.BEARER``),
and every later request of the session the same header; a request's body
is at most ``MAX_REQUEST_BYTES`` (413) of JSON under the rules of frames
(``rwt_protocol.codecs.json``: nesting, integers, UTF-8; else 400 with a JSON-RPC
parse error), and only an ``initialize`` request opens a session (400, before
anything is built; D41); a session has at most ``MAX_REQUESTS_IN_FLIGHT`` requests at
once (429); ``--allowed-origins`` applies (403). Each tool call passes the
session's ``rwt_mcp.guard.Guard``, whose access refusals go through the server's one
access gate and its log line. Refusals are logged once per episode.

MCP is an HTTP front end of the registry (``frontends_registry.MCP``), off unless
``ServerConfig.mcp`` is set. Its requests' sockets are slots of the server
(``FrontEndHost.take_slot``, ``join_socket``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hmac
import json
import logging
import os
import re
import time
import uuid
from collections import OrderedDict
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

import anyio
import h11
from mcp.server._streamable_http_modern import handle_modern_request
from mcp.server.request_state import RequestStateSecurity
from mcp.server.runner import serve_loop
from mcp.server.streamable_http import MCP_SESSION_ID_HEADER, StreamableHTTPServerTransport
from mcp.server.transport_security import TransportSecuritySettings
from mcp.shared.inbound import MCP_PROTOCOL_VERSION_HEADER
from mcp.types import (
    INVALID_REQUEST,
    PARSE_ERROR,
    CallToolResult,
    ErrorData,
    JSONRPCError,
    TextContent,
)
from mcp.types.version import HANDSHAKE_PROTOCOL_VERSIONS

from rwt_graph.ratelog import EpisodeLog
from rwt_graph.safety.rules import APPROVAL_TIMEOUT_S
from rwt_mcp.app import AppSite
from rwt_mcp.approval import Approvals
from rwt_mcp.guard import Guard
from rwt_mcp.link import RobotLink
from rwt_mcp.session import McpSession
from rwt_mcp.tasks import MAX_TASKS, TaskStore
from rwt_mcp.tools import build_server, release_server, warm_up
from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.credentials import AuthMode, EntryAuth
from rwt_protocol.errors import ConfigError, RemoteProtocolError
from rwt_protocol.runtime.access import log_refused

from ..admission.shares import HostShares, address_of
from ..frontends import FrontEnd
from ..memory import MemoryConnection, memory_pair
from ..pump import ConnectionPump, drive_timers, run_connection
from .endpoint import bearer, claims_path, open_request, reply
from .host_rates import HostPace
from .mcp_options import MCP_PATH, METADATA_PATH, McpOptions

if TYPE_CHECKING:
    from collections.abc import AsyncIterator, Callable

    from anyio.abc import ByteStream, TaskGroup, TaskStatus
    from mcp.server.lowlevel import Server

    from rwt_graph.safety.envelope import Envelope
    from rwt_mcp.resources import Watched
    from rwt_protocol.runtime.request import SessionRequest

    from ..host import FrontEndHost
    from .mcp_siblings import McpSiblings

__all__ = [
    "HOST_REFUSAL_WAIT_S",
    "HOST_SESSIONS_PER_S",
    "HOST_SESSION_WAIT_S",
    "MAX_REQUESTS_IN_FLIGHT",
    "MAX_REQUEST_BYTES",
    "MODERN_HOSTS_KEPT",
    "REQUEST_STATE_TTL_S",
    "SESSION_SLOTS",
    "McpEndpoint",
    "mcp_endpoint",
]

logger = logging.getLogger("rwt.mcp")
_episodes = EpisodeLog(logger)  # a peer can trigger these at will

MAX_REQUEST_BYTES = 1024 * 1024
"""Largest body of a request to ``/mcp`` (one JSON-RPC message or batch): 413."""
MAX_REQUESTS_IN_FLIGHT = 8
"""Requests of one MCP session served at once (its event stream counts); one more: 429."""
SESSION_SLOTS = 2
"""Connection slots an MCP session holds (``--max-connections``, the host's share): itself
with its event stream, and one request at once, as the official client holds them; a
request beyond them takes one more slot while it runs, or gets 503 (D40)."""
MODERN_HOSTS_KEPT = 256
"""Hosts whose 2026-07-28 requests' rate caps are kept (``rwt_mcp.guard.Guard``, per host:
a request has no session); past them the least recently seen host's are dropped."""

HOST_SESSIONS_PER_S = 20.0
"""MCP sessions one host may open a second: a 2025-era ``initialize``, or a 2026-07-28 request
(each is a session of its own, its server built), spaced ``1 / 20`` s apart
(``host_rates.HostPace``): one that comes early waits its turn, up to
``HOST_SESSION_WAIT_S``; past that it is refused before anything is built for it (a tool
call gets a tool error naming the bound, another request a JSON-RPC error with 429). A
flood from one host then costs the event loop one session at a time, never a burst
(docs/limits.md). The requests of an open 2025-era session are bounded by its own caps."""
HOST_SESSION_WAIT_S = 1.0
"""The longest a new session waits for its host's turn (``HOST_SESSIONS_PER_S``), seconds."""
HOST_REFUSAL_WAIT_S = 1.0
REQUEST_STATE_TTL_S = 600.0
"""Seconds a 2026-07-28 round's request state stays valid at least (the SDK's default): past
it the next round is refused as stale (D69)."""
"""Seconds a refused session waits for its answer: a client sending back to back gets a
few answers a second per connection, not as many as the server can write (the wait holds
a socket, not the event loop)."""

_METHODS = (b"POST", b"GET", b"DELETE", b"OPTIONS")
_HOST = re.compile(r"[^A-Za-z0-9.:\[\]_-]")  # what a Host header may keep in a URL
_READ_SIZE = 65536
_CORS = [
    (b"Access-Control-Allow-Methods", b"POST, GET, DELETE, OPTIONS"),
    (
        b"Access-Control-Allow-Headers",
        b"Authorization, Content-Type, Accept, Mcp-Session-Id, Mcp-Protocol-Version, Mcp-Method,"
        b" Mcp-Name, Last-Event-ID",
    ),
    (b"Access-Control-Expose-Headers", b"Mcp-Session-Id, WWW-Authenticate"),
    (b"Access-Control-Max-Age", b"600"),
]
# our own Origin check (--allowed-origins) replaces the SDK's Host check
_NO_SDK_CHECK = TransportSecuritySettings(enable_dns_rebinding_protection=False)


def _not_a_closed_event_stream(record: logging.LogRecord) -> bool:
    """Drop the SDK's traceback for an event stream its own ``terminate`` closed.

    A client's ``DELETE`` while its event stream (GET) is open makes the SDK's
    transport close that stream under its writer, which logs the end as an
    error with a traceback (mcp 1.x); it is the session's normal end.
    """
    closed = record.exc_info is not None and isinstance(
        record.exc_info[1], anyio.ClosedResourceError
    )
    return not (closed and record.getMessage() == "Error in standalone SSE writer")


logging.getLogger("mcp.server.streamable_http").addFilter(_not_a_closed_event_stream)


@dataclass
class _Session:
    """One MCP session: its transport, the token that opened it, requests in flight.

    ``runtime``: its session on the connection runtime (each request is its input,
    ``--idle-timeout``). ``slot``: the host of the slot it holds besides its
    session's (``SESSION_SLOTS``), given back when it ends.
    """

    transport: StreamableHTTPServerTransport
    token: str | None
    runtime: McpSession
    slot: str
    in_flight: int = 0

    @property
    def client_id(self) -> str:
        """The session's id in the graph and the logs."""
        return self.runtime.client_id


def _make_session(request: SessionRequest) -> McpSession:
    return McpSession(
        request.graph,
        request.client_id,
        config=request.rules,
        on_output=request.on_output,
        peer=request.peer,
        on_closed=request.on_closed,
        memory=request.memory,
    )


_FRONTEND = FrontEnd("mcp", (), _make_session, AuthMode.BEARER)
"""The MCP sessions' protocol on the runtime: ``rwt_mcp.session.McpSession``."""


@dataclass
class _Admitted:
    """An MCP session admitted by the server, not yet running.

    ``pump`` and ``connection``: a 2025-era session's pump (the runtime's timers,
    ``--idle-timeout``, its close) over a connection that carries no frames; None
    for a 2026-07-28 request's, which lives as long as its request.
    """

    session: McpSession
    pump: ConnectionPump | None = None
    connection: MemoryConnection | None = None

    @asynccontextmanager
    async def running(self) -> AsyncIterator[McpSession]:
        """Run the session; yield it, and close it after.

        With a pump, the runtime closing the session (``--idle-timeout``, the
        server stopping) ends what the caller runs with it. Without, the session
        is the caller's to the end, its timers driven by one task
        (``pump.drive_timers``: its calls' deadlines, its throttles).
        """
        if self.pump is None:
            self.session.start(anyio.current_time())
            try:
                async with anyio.create_task_group() as work:
                    self.session.bind(work, anyio.current_time)
                    self.session.on_close_requested = work.cancel_scope.cancel
                    work.start_soon(drive_timers, self.session)
                    try:
                        yield self.session
                    finally:
                        work.cancel_scope.cancel()  # the goals' watchers, the timers
            finally:
                self.session.close()
            return
        async with anyio.create_task_group() as tg:

            async def pump() -> None:
                assert self.pump is not None  # checked above
                await run_connection(self.pump, self.session)
                tg.cancel_scope.cancel()  # closed by the runtime: the MCP session ends

            tg.start_soon(pump)
            self.session.bind(tg, anyio.current_time)
            try:
                yield self.session
            finally:
                assert self.connection is not None  # made with the pump
                await _close_pair(self.connection)


def _no_output() -> None:
    """A 2026-07-28 request's session sends no frames: nothing to wake."""


async def _close_pair(connection: MemoryConnection) -> None:
    """Close both ends of an in-process connection (the server's too, if its pump did not)."""
    await connection.aclose()
    connection.channel.inbound.close()
    connection.channel.outbound.close()


class McpEndpoint:
    """Answers MCP requests on the WebSocket port (``/mcp``).

    Args:
        host: admits the sessions and holds the access rules (``host.FrontEndHost``).
        options: the MCP settings.
        allowed_origins: fnmatch patterns of accepted ``Origin`` headers
            (``--allowed-origins``); empty: any origin.
    """

    def __init__(
        self,
        host: FrontEndHost,
        options: McpOptions,
        allowed_origins: tuple[str, ...] = (),
    ) -> None:
        self.host = host
        self.options = options
        self.allowed_origins = allowed_origins
        self.entry: EntryAuth = host.entry
        if options.bearer_token is not None:  # its own check of the tokens, set by embedding code
            self.entry = dataclasses.replace(self.entry, token=options.bearer_token)
        self.auth_required = self.entry.required
        self.sessions: dict[str, _Session] = {}
        self.siblings = options.siblings  # the other workers' (--workers; mcp_siblings)
        new_id = None if self.siblings is None else self.siblings.new_id
        self._new_id = new_id or (lambda: uuid.uuid4().hex)
        # every session's and request's (rwt_mcp.tasks), each host with its share of them (D60)
        self.tasks = TaskStore(new_id=new_id, shares=HostShares(MAX_TASKS))
        self._watched: Watched = {}  # topics the 2026-07-28 requests' listen streams hold
        self._modern_guards: OrderedDict[str, Guard] = OrderedDict()
        self._tg: TaskGroup | None = None
        self._forwarded: anyio.CancelScope | None = None
        self._host_pace = HostPace(HOST_SESSIONS_PER_S, HOST_SESSION_WAIT_S, MODERN_HOSTS_KEPT)
        self.request_state = _request_state(self.siblings, host.graph.safety)
        """How every server of this front end seals a 2026-07-28 round's request state: any
        of them (and any worker's) takes the next round (a person's approval, D69)."""
        warm_up()  # before the server freezes its start-up objects (gcfreeze)

    def _approvals(self, client: str) -> Approvals | None:
        """What a session's tool calls ask a person first: the graph's safety rules' (D69)."""
        envelope = self.host.graph.safety
        if envelope is None:
            return None
        return Approvals(envelope.rules, client, envelope.record_approval)

    def bind(self, tg: TaskGroup | None) -> None:
        """Run sessions in ``tg`` (the server's connections); None: open no new ones.

        A worker of ``--workers`` also takes the requests the others pass it
        (``mcp_siblings``) while bound.
        """
        self._tg = tg
        if tg is None and self._forwarded is not None:
            self._forwarded.cancel()
            self._forwarded = None
        elif tg is not None and self.siblings is not None and self._forwarded is None:
            self._forwarded = anyio.CancelScope()
            tg.start_soon(self._take_forwarded, self._forwarded)

    async def _take_forwarded(self, scope: anyio.CancelScope) -> None:
        """Answer the requests of the sessions and tasks this worker holds (``mcp_siblings``)."""
        assert self.siblings is not None  # only bound so
        with scope:
            try:
                await self.siblings.serve(functools.partial(self.serve, forwarded=True))
            except OSError as exc:  # its sessions and tasks answer only on sockets it accepts
                logger.warning("event=mcp_siblings_unavailable error=%r", exc)

    @staticmethod
    def claims(head: bytes) -> bool | None:
        """Whether the request starting with ``head`` is MCP's; None: too short to tell.

        MCP's are ``MCP_PATH`` and the protected-resource metadata (``METADATA_PATH``).
        """
        mcp = claims_path(head, _METHODS, MCP_PATH, lambda _method, after: after in (b" ", b"?"))
        if mcp is not False:
            return mcp
        return claims_path(
            head, (b"GET", b"OPTIONS"), METADATA_PATH, lambda _m, after: after in (b" ", b"/", b"?")
        )

    async def serve(
        self, stream: ByteStream, head: bytes, peer: str, *, forwarded: bool = False
    ) -> None:
        """Answer the one request on ``stream`` whose first bytes are ``head``, then return.

        The caller bounds the time until the request is read (the handshake
        timeout); an admitted request then runs as long as MCP needs (an event
        stream, a long tool call), bounded per session by ``MAX_REQUESTS_IN_FLIGHT``.
        A worker passes a request of another worker's session or task to it
        (``mcp_siblings``); ``forwarded``: this one was passed here, and is answered here.
        """
        opened = await open_request(
            stream,
            head,
            limit=MAX_REQUEST_BYTES,
            too_large=f"the request is over {MAX_REQUEST_BYTES} bytes",
            allowed_origins=self.allowed_origins,
            cors=_CORS,
        )
        if opened is None:
            return
        conn, request, headers, cors = opened.conn, opened.request, opened.headers, opened.cors
        exchange = _Exchange(conn, stream, request, opened.body, peer, cors, headers)
        path = request.target.decode("latin-1").split("?", 1)[0]
        if path in (METADATA_PATH, METADATA_PATH + MCP_PATH):
            body = "" if request.method == b"OPTIONS" else json.dumps(self._metadata(headers))
            await reply(conn, stream, 204 if not body else 200, body, cors, "application/json")
            return
        opens = request.method == b"POST" and MCP_SESSION_ID_HEADER not in headers
        # a request another worker passed here took its turn there
        answered, paced = (False, True) if forwarded else await self._pass_on(exchange, opens)
        if answered:
            return
        refusal = self._refusal(request, headers, peer)
        if refusal is not None:
            extra = [(b"WWW-Authenticate", self._challenge(headers))] if refusal[0] == 401 else []
            await exchange.refuse(*refusal, extra)
            return
        if request.method == b"OPTIONS":
            await reply(conn, stream, 204, "", cors)
            return
        session_id = headers.get(MCP_SESSION_ID_HEADER)
        modern = session_id is None and _modern(headers)
        if request.method == b"POST":
            problem = _body_refusal(opened.body, new_session=session_id is None and not modern)
            if problem is not None:
                await exchange.refuse_jsonrpc(*problem)
                return
            if opens and not paced and not await self._take_turn(exchange):
                return
        if modern:
            await self._modern(exchange, self._site(headers))
        elif session_id is None:
            await self._open(exchange, bearer(headers), self._site(headers))
        else:
            await self._continue(exchange, self.sessions[session_id])

    async def _pass_on(self, exchange: _Exchange, opens: bool) -> tuple[bool, bool]:
        """Pass a request of another worker's session or task to it: (answered, paced).

        A task's request opens a session where it is answered: it takes its turn
        here first (``_take_turn``), where it came in. Not answered: it is this
        worker's, or its owner is gone (answered here as an unknown one).
        """
        owner = self._owner(exchange.headers, exchange.body)
        if owner is None:
            return False, False
        if opens and not await self._take_turn(exchange):  # a task's: valid JSON (_owner)
            return True, True
        return await self._forward(exchange, owner), True

    async def _take_turn(self, exchange: _Exchange) -> bool:
        """Wait for the host's turn to open a session (``HOST_SESSIONS_PER_S``).

        False: past ``HOST_SESSION_WAIT_S``, refused and answered (a tool error, a 429).
        """
        wait = self._host_pace.turn(exchange.peer)
        if wait is None:
            await _refuse_host_rate(exchange)
            return False
        await anyio.sleep(wait)
        return True

    def _owner(self, headers: dict[str, str], body: bytes) -> int | None:
        """The other worker holding the request's session or task; None: this one, or none."""
        if self.siblings is None:
            return None
        session_id = headers.get(MCP_SESSION_ID_HEADER)
        if session_id is not None:
            return self.siblings.owner(session_id)
        if b'"tasks/' not in body:  # the cheap test first: most requests name no task
            return None
        try:
            message = decode_json_text(body, "Parse error")
        except RemoteProtocolError:
            return None  # refused where it is answered
        params = message.get("params") if isinstance(message, dict) else None
        task_id = params.get("taskId") if isinstance(params, dict) else None
        method = message.get("method") if isinstance(message, dict) else None
        if not isinstance(task_id, str) or not str(method).startswith("tasks/"):
            return None
        return self.siblings.owner(task_id)

    async def _forward(self, exchange: _Exchange, owner: int) -> bool:
        """Pass the request to worker ``owner``; False: it is gone (answered here, then).

        Its socket here takes a connection slot while the answer is relayed (D40).
        """
        assert self.siblings is not None  # an owner is only found so
        slot = self.host.take_slot("mcp", exchange.peer)
        if slot is None:
            await exchange.refuse(503, "too many connections")
            return True
        self.host.join_socket()  # an event stream or a long call outlives the handshake
        try:
            return await self.siblings.forward(
                owner, exchange.peer, exchange.request, exchange.body, exchange.stream
            )
        finally:
            self.host.give_slot(slot)

    def _base(self, headers: dict[str, str]) -> str:
        """``http(s)://HOST[:PORT]`` as the client reached the endpoint (its ``Host`` header)."""
        settings = self.host.settings
        scheme = "https" if settings.tls else "http"
        host = _HOST.sub("", headers.get("host", ""))[:255]  # the peer's text, in a header
        return f"{scheme}://{host or f'{settings.host}:{settings.port}'}"

    def _site(self, headers: dict[str, str]) -> AppSite:
        """Where the robot app finds this server's video, as the client reached it."""
        base = self._base(headers)
        video = None
        if self.options.video_port is not None:
            host = urlsplit(base).hostname or self.host.settings.host
            host = f"[{host}]" if ":" in host else host  # an IPv6 address, in a URL
            video = f"http://{host}:{self.options.video_port}"  # the video server: no TLS
        webrtc = "webrtc" in self.host.features().transports
        return AppSite(base=base, webrtc=webrtc, video=video, auth=self.auth_required)

    def _metadata(self, headers: dict[str, str]) -> dict[str, Any]:
        """The protected-resource metadata of ``/mcp`` (RFC 9728 section 2; D52)."""
        document: dict[str, Any] = {
            "resource": self._base(headers) + MCP_PATH,
            "bearer_methods_supported": ["header"],
            "resource_name": "rwt MCP server",
            "resource_documentation": "https://modelcontextprotocol.io",
        }
        server = self.options.authorization_server
        if server is not None:
            document["authorization_servers"] = [server]
        return document

    def _challenge(self, headers: dict[str, str]) -> bytes:
        """A 401's ``WWW-Authenticate``: Bearer, naming the metadata (RFC 9728 section 5.1)."""
        url = self._base(headers) + METADATA_PATH + MCP_PATH
        return f'Bearer resource_metadata="{url}"'.encode("latin-1")

    def _refusal(
        self, request: h11.Request, headers: dict[str, str], peer: str
    ) -> tuple[int, str] | None:
        """Why the request is refused before MCP sees it (status, text), or None."""
        path, _, query = request.target.decode("latin-1").partition("?")
        if path != MCP_PATH:
            return 404, f"the MCP endpoint is {MCP_PATH}, not {path}"
        if request.method == b"OPTIONS":
            return None
        credential = _credential_refusal(headers, query)
        if credential is not None:
            return 401, credential
        session_id = headers.get(MCP_SESSION_ID_HEADER)
        token = bearer(headers)
        if session_id is None:
            if request.method != b"POST":
                return 400, "no Mcp-Session-Id: POST an initialize request first"
            entry = self.entry.check(AuthMode.BEARER, peer, headers=headers, now=time.monotonic())
            return None if entry is None else (entry.status, entry.text)
        session = self.sessions.get(session_id)
        if session is None:
            return 404, f"no MCP session {session_id[:64]}: initialize a new one"
        if session.token is not None and (
            token is None or not hmac.compare_digest(token.encode(), session.token.encode())
        ):
            return 401, "the bearer token is not the one that opened this MCP session"
        if session.in_flight >= MAX_REQUESTS_IN_FLIGHT:
            return 429, f"{MAX_REQUESTS_IN_FLIGHT} requests of this MCP session are in flight"
        return None

    async def _open(self, exchange: _Exchange, token: str | None, site: AppSite) -> None:
        """A request without a session: admit a new session and let it answer (initialize).

        The session takes ``SESSION_SLOTS`` slots: one more (taken first) beside its own.
        """
        tg = self._tg
        slot = None if tg is None else self.host.take_slot("mcp", exchange.peer)
        admitted = None if slot is None else await self._admit(exchange.peer)
        if tg is None or slot is None or admitted is None:
            if slot is not None:
                self.host.give_slot(slot)
            await exchange.refuse(503, "too many connections")
            return
        transport = StreamableHTTPServerTransport(
            mcp_session_id=self._new_id(),
            security_settings=_NO_SDK_CHECK,
        )  # no idle timeout of the SDK's: the runtime's (--idle-timeout, D40)
        session_id = transport.mcp_session_id
        assert session_id is not None  # given just above
        session = _Session(transport, token if self.auth_required else None, admitted.session, slot)
        self.sessions[session_id] = session
        established = False
        try:
            await tg.start(self._run, session_id, session, admitted, site, exchange.peer)
            status = await self._handle(exchange, session)
            established = status is not None and status < 400
        finally:
            if not established:
                await self._discard(session_id)

    async def _admit(self, peer: str, *, pumped: bool = True) -> _Admitted | None:
        """The server's admission for a new MCP session (``rwt_mcp.session.McpSession``).

        ``pumped``: run it under a pump (a 2025-era session); False for a
        2026-07-28 request's, which needs no timers of the runtime's.
        """
        pump = connection = None
        on_output: Callable[[], None] = _no_output
        if pumped:
            channel, connection = memory_pair()
            channel.transport = "mcp"  # in the logs: an MCP session's connection
            pump = ConnectionPump(channel, self.host.flow, self.host.admission)
            on_output = pump.wake
        # no socket of its own: its host's share applies from the first session (D40)
        session = self.host.open_session(
            "mcp",
            peer,
            on_output,
            frontend=_FRONTEND,
            authenticated=True,
            share_from_first=True,
        )
        if not isinstance(session, McpSession):
            if connection is not None:
                await _close_pair(connection)
            return None
        session.request_scoped = (
            not pumped
        )  # a 2026-07-28 request: a command, not a commander (D68)
        return _Admitted(session, pump, connection)

    async def _continue(self, exchange: _Exchange, session: _Session) -> None:
        """A request of a session: the socket joins it (no handshake deadline), MCP answers.

        Past ``SESSION_SLOTS`` requests in flight its socket takes a slot of its
        own (D40), or the request gets 503.
        """
        slot = None
        if session.in_flight >= SESSION_SLOTS:  # the session's own slots are in use
            slot = self.host.take_slot("mcp", exchange.peer)
            if slot is None:
                await exchange.refuse(503, "too many connections")
                return
        self.host.join_socket()
        try:
            await self._handle(exchange, session)
        finally:
            if slot is not None:
                self.host.give_slot(slot)
        if session.transport.is_terminated and session.transport.mcp_session_id:
            await self._discard(session.transport.mcp_session_id)  # the client's DELETE

    async def _handle(self, exchange: _Exchange, session: _Session) -> int | None:
        session.in_flight += 1
        session.runtime.begin_request(anyio.current_time())  # input, held until answered
        try:
            return await exchange.run(session.transport.handle_request)
        finally:
            session.in_flight -= 1
            session.runtime.end_request(anyio.current_time())  # the idle time counts from here

    async def _run(
        self,
        session_id: str,
        session: _Session,
        admitted: _Admitted,
        site: AppSite,
        peer: str,
        *,
        task_status: TaskStatus[None],
    ) -> None:
        """One MCP session, to its end (DELETE, idle, the server stopping, its connection gone)."""
        started = False
        try:
            async with admitted.running() as robot:
                link = RobotLink(robot.url, robot)
                await link.connect(anyio.Event())  # at once: the graph is here
                guard = Guard(session.client_id, self.options.read_only)
                mcp, tasks = build_server(
                    link,
                    guard,
                    self.tasks,
                    site=site,
                    host=self._host(peer),
                    approvals=self._approvals(session.client_id),
                    request_state=self.request_state,
                )
                try:
                    async with session.transport.connect() as (read, write):
                        task_status.started()
                        started = True
                        await _serve(mcp._lowlevel_server, session.transport, read, write)
                    await tasks.hold()  # the goals it started as tasks
                finally:
                    await link.close()
        except Exception:  # a bug ends this session only
            logger.exception("event=bug task=mcp_session client=%s", session.client_id)
        finally:
            if not started:
                task_status.started()
            await self._discard(session_id)

    async def _modern(self, exchange: _Exchange, site: AppSite) -> None:
        """A 2026-07-28 request: one ``McpSession`` for it, answered by the SDK (D52).

        The session takes one connection slot (its socket's) while the request
        runs, and while a goal it started as a task runs (``rwt_mcp.tasks``).
        """
        tg = self._tg
        admitted = None if tg is None else await self._admit(exchange.peer, pumped=False)
        if tg is None or admitted is None:
            await exchange.refuse(503, "too many connections")
            return
        self.host.join_socket()
        answered = anyio.Event()
        try:
            mcp = await tg.start(self._run_modern, admitted, exchange.peer, answered, site)
            if mcp is None:  # its connection failed before it could run (logged)
                await exchange.refuse(503, "the MCP request's connection failed")
                return
            entry = functools.partial(handle_modern_request, mcp, _NO_SDK_CHECK, False, {})
            admitted.session.begin_request(anyio.current_time())
            try:
                await exchange.run(entry)
            finally:
                admitted.session.end_request(anyio.current_time())
        finally:
            answered.set()

    async def _run_modern(
        self,
        admitted: _Admitted,
        peer: str,
        answered: anyio.Event,
        site: AppSite,
        *,
        task_status: TaskStatus[Server[Any] | None],
    ) -> None:
        """A 2026-07-28 request's session: until it is answered and its tasks' goals end."""
        started = False
        try:
            async with admitted.running() as robot:
                link = RobotLink(robot.url, robot)
                await link.connect(anyio.Event())  # at once: the graph is here
                guard = self._modern_guard(peer)
                mcp, tasks = build_server(
                    link,
                    guard,
                    self.tasks,
                    self._watched,
                    site,
                    self._host(peer),
                    approvals=self._approvals(admitted.session.client_id),
                    request_state=self.request_state,
                )
                try:
                    task_status.started(mcp._lowlevel_server)
                    started = True
                    await answered.wait()
                    await tasks.hold()
                finally:
                    release_server(mcp)
                    await link.close()
        except Exception:  # a bug ends this request only
            logger.exception("event=bug task=mcp_request client=%s", admitted.session.client_id)
        finally:
            if not started:
                task_status.started(None)

    def _host(self, peer: str) -> str:
        """The host ``peer`` (``ADDRESS:PORT``) counts as for the shares (``--host-prefix-v4``)."""
        return self.host.host_prefixes.host(address_of(peer))

    def _modern_guard(self, peer: str) -> Guard:
        """A 2026-07-28 request's rules: its host's rate caps (``MODERN_HOSTS_KEPT``)."""
        host = peer.rpartition(":")[0] or peer
        guard = self._modern_guards.get(host)
        if guard is None:
            guard = Guard(f"mcp:{host}", self.options.read_only)
            self._modern_guards[host] = guard
            if len(self._modern_guards) > MODERN_HOSTS_KEPT:
                self._modern_guards.popitem(last=False)
        self._modern_guards.move_to_end(host)
        return guard

    async def _discard(self, session_id: str) -> None:
        """Forget the session (its id answers 404 from now) and end its transport."""
        session = self.sessions.pop(session_id, None)
        if session is not None:
            self.host.give_slot(session.slot)
            with anyio.CancelScope(shield=True):
                await session.transport.terminate()


def _request_state(siblings: McpSiblings | None, envelope: Envelope | None) -> RequestStateSecurity:
    """The sealing of request states: the workers' shared key (``--workers``), else this one's.

    It lives at least ``REQUEST_STATE_TTL_S``, and twice the time a person has to
    answer an approval, so a late answer is told it is late, not refused as stale.
    """
    key = os.urandom(32) if siblings is None else siblings.state_key()
    timeout = APPROVAL_TIMEOUT_S if envelope is None else envelope.rules.approval_timeout_s
    return RequestStateSecurity(keys=[key], ttl=max(REQUEST_STATE_TTL_S, 2 * timeout))


async def _serve(
    mcp: Server[Any], transport: StreamableHTTPServerTransport, read: Any, write: Any
) -> None:
    """Run the MCP server on the transport's streams until they end (DELETE, its session's end)."""
    async with mcp.lifespan(mcp) as state:
        await serve_loop(
            mcp, read, write, lifespan_state=state, session_id=transport.mcp_session_id
        )


async def _refuse_host_rate(exchange: _Exchange) -> None:
    """Answer a session over ``HOST_SESSIONS_PER_S``, after ``HOST_REFUSAL_WAIT_S``.

    A tool call gets a tool error naming the bound (what the agent shows its model),
    another request a JSON-RPC error (429); the access log has one line per episode.
    """
    await anyio.sleep(HOST_REFUSAL_WAIT_S)
    why = f"over {HOST_SESSIONS_PER_S:g} MCP sessions a second from this host"
    message = decode_json_text(exchange.body, "Parse error")  # checked: _body_refusal
    method = message.get("method") if isinstance(message, dict) else None
    params = message.get("params") if isinstance(message, dict) else None
    tool = params.get("name") if isinstance(params, dict) else None
    op = str(tool if method == "tools/call" and isinstance(tool, str) else method)[:64]
    log_refused(
        client=f"mcp:{exchange.peer}",
        op=op,
        rule="HOST_SESSIONS_PER_S",
        reason=why,
        now=time.monotonic(),
    )
    text = f"{op}: {why} (HOST_SESSIONS_PER_S): wait and call again"
    if method != "tools/call" or not isinstance(message, dict):
        await exchange.refuse_jsonrpc(429, text, INVALID_REQUEST, [(b"Retry-After", b"1")])
        return
    result = CallToolResult(
        content=[TextContent(type="text", text=f"Error executing tool {op}: {text}")],
        is_error=True,
    )
    answer = {
        "jsonrpc": "2.0",
        "id": message.get("id"),
        "result": result.model_dump(mode="json", by_alias=True, exclude_none=True),
    }
    await reply(
        exchange.conn,
        exchange.stream,
        200,
        json.dumps(answer, separators=(",", ":")),
        exchange.cors,
        "application/json",
    )


def _body_refusal(body: bytes, *, new_session: bool) -> tuple[int, str, int] | None:
    """Why a POST's body is refused before MCP sees it: (HTTP status, text, JSON-RPC code).

    The body is JSON under the rules of rosbridge frames (``decode_json_text``:
    UTF-8, ``MAX_NESTING`` levels, integers within 64 bits), which the SDK's
    parser cannot bound (a deep one or a long integer made it answer 500 with a
    traceback); without a session id only an ``initialize`` request may come,
    refused before a session is built for it (docs/mcp.md, D41).
    """
    try:
        message = decode_json_text(body, "Parse error")
    except RemoteProtocolError as exc:
        return 400, exc.message, PARSE_ERROR
    if new_session and not (
        isinstance(message, dict) and message.get("method") == "initialize" and "id" in message
    ):
        text = "Bad Request: no Mcp-Session-Id: only an initialize request opens a session"
        return 400, text, INVALID_REQUEST
    return None


def _modern(headers: dict[str, str]) -> bool:
    """Whether a request without a session is of a revision without the handshake (2026-07-28).

    The ``MCP-Protocol-Version`` header decides, as the SDK's session manager routes: a
    handshake-era version, or none, is a 2025-era request (D52).
    """
    version = headers.get(MCP_PROTOCOL_VERSION_HEADER)
    return version is not None and version not in HANDSHAKE_PROTOCOL_VERSIONS


def _credential_refusal(headers: dict[str, str], query: str) -> str | None:
    """Why the request's credentials are refused, whatever ``--auth-secret-file`` says, or None.

    Only ``Authorization: Bearer`` is taken (RFC 6750 section 2.1, as MCP's
    authorization asks): another scheme (``Basic``, rosbridge's ``MAC``) and a
    token in the URL's query (``token=``, ``access_token=``: a video stream's way)
    are refused, never ignored (D52).
    """
    scheme = headers.get("authorization", "").partition(" ")[0]
    if scheme and scheme.lower() != "bearer":
        return f"the Authorization scheme {scheme[:32]!r} is not taken here: send Bearer <token>"
    names = {part.partition("=")[0].lower() for part in query.split("&")}
    if names & {"token", "access_token"}:
        return "a token in the URL is refused: send it as Authorization: Bearer <token>"
    return None


def _log_refusal(peer: str, status: int, text: str) -> None:
    """``event=mcp_refused``, once per episode of each status (docs/limits.md, logs)."""
    _episodes.log(
        logging.INFO,
        f"mcp_refused:{status}",
        "event=mcp_refused peer=%s status=%d reason=%r",
        peer,
        status,
        text[:200],
    )


class _Exchange:
    """One HTTP request read, answered by an ASGI app over its socket (``Connection: close``)."""

    def __init__(
        self,
        conn: h11.Connection,
        stream: ByteStream,
        request: h11.Request,
        body: bytes,
        peer: str,
        cors: list[tuple[bytes, bytes]],
        headers: dict[str, str],
    ) -> None:
        self.conn, self.stream, self.request, self.body = conn, stream, request, body
        self.peer, self.cors, self.headers = peer, cors, headers
        self.status: int | None = None
        self._answered = False  # the response's last byte went out
        self._waiting: anyio.CancelScope | None = None  # a ``_receive`` waiting on the socket

    async def refuse(
        self, status: int, text: str, extra: list[tuple[bytes, bytes]] | None = None
    ) -> None:
        """Answer ``status`` with ``text`` (logged once per episode of that status)."""
        _log_refusal(self.peer, status, text)
        await reply(self.conn, self.stream, status, text, self.cors + (extra or []))

    async def refuse_jsonrpc(
        self, status: int, text: str, code: int, extra: list[tuple[bytes, bytes]] | None = None
    ) -> None:
        """Answer ``status`` with a JSON-RPC error ``code`` saying ``text``, as the SDK does."""
        _log_refusal(self.peer, status, text)
        error = JSONRPCError(
            jsonrpc="2.0", id="server-error", error=ErrorData(code=code, message=text)
        )
        body = error.model_dump_json(by_alias=True, exclude_none=True)
        headers = self.cors + (extra or [])
        await reply(self.conn, self.stream, status, body, headers, "application/json")

    async def run(self, app: Callable[..., Any]) -> int | None:
        """Run ``app`` (ASGI 3) for the request; the response's status, None if none was sent."""
        target = self.request.target.decode("latin-1")
        path, _, query = target.partition("?")
        host, _, port = self.peer.rpartition(":")
        scope = {
            "type": "http",
            "asgi": {"version": "3.0", "spec_version": "2.3"},
            "http_version": "1.1",
            "method": self.request.method.decode(),
            "scheme": "http",
            "path": path,
            "raw_path": path.encode("latin-1"),
            "query_string": query.encode("latin-1"),
            "root_path": "",
            "headers": [(k.lower(), v) for k, v in self.request.headers],
            "client": (host.strip("[]"), int(port) if port.isdigit() else 0),
            "server": None,
        }
        with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            await app(scope, self._receive, self._send)
        return self.status

    async def _receive(self) -> dict[str, Any]:
        """The body, then (waiting on the socket) the client's disconnect, or the answer's end.

        Once the response is sent the exchange is over, and a waiting ``_receive``
        says so (``_send``): the SDK's watcher of the disconnect then returns
        instead of being canceled, which would leave a reference cycle (its
        ``CancelledError`` and its frames) for the collector with each request.
        """
        if self.body is not None:
            body, self.body = self.body, None  # type: ignore[assignment]
            return {"type": "http.request", "body": body, "more_body": False}
        if not self._answered:
            with anyio.CancelScope() as self._waiting:
                while True:  # bytes after the request are dropped: one request per connection
                    try:
                        await self.stream.receive(_READ_SIZE)
                    except (
                        anyio.EndOfStream,
                        anyio.BrokenResourceError,
                        anyio.ClosedResourceError,
                        OSError,
                    ):
                        break
            self._waiting = None
        return {"type": "http.disconnect"}

    async def _send(self, message: dict[str, Any]) -> None:
        if message["type"] == "http.response.start":
            self.status = int(message["status"])
            kept = [(k, v) for k, v in message.get("headers", []) if k.lower() != b"connection"]
            fields = [*kept, *self.cors, (b"Connection", b"close")]  # one request a connection
            data = self.conn.send(h11.Response(status_code=self.status, headers=fields))
        elif message["type"] == "http.response.body":
            data = b""
            if message.get("body"):
                data += self.conn.send(h11.Data(data=message["body"])) or b""
            if not message.get("more_body", False):
                data += self.conn.send(h11.EndOfMessage()) or b""
        else:
            return
        if data:
            await self.stream.send(data)
        if message["type"] == "http.response.body" and not message.get("more_body", False):
            self._answered = True
            if self._waiting is not None:  # the watcher of the disconnect: it returns now
                self._waiting.cancel()
                await anyio.lowlevel.checkpoint()


def mcp_endpoint(host: FrontEndHost, options: object) -> McpEndpoint:
    """The MCP endpoint of ``host`` (``frontends_registry.MCP``).

    Raises:
        ConfigError: ``options`` is not an ``McpOptions``.
    """
    if not isinstance(options, McpOptions):
        raise ConfigError(f"MCP's options must be McpOptions, not {type(options).__name__}")
    return McpEndpoint(host, options, host.settings.allowed_origins)
