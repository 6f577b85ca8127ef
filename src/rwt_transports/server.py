"""The server: listeners on every transport, one graph, the registry's front ends on it.

``GraphServer`` (``RosbridgeServer``, its first name, is the same class) owns the
graph and runs the listeners configured in ``ServerConfig`` side by side:
WebSocket (``ws``/``wss``), TCP (plain or TLS), UDP and stdio. The protocols it
speaks are the front ends of the registry (``frontends_registry``): rosbridge by
default, the others chosen by WebSocket subprotocol, WebRTC data-channel label or
HTTP path; nothing here names one. Every connection, whatever its transport and
its protocol, is admitted in one step (``admit``, or ``open_session``:
``--max-connections``, the host shares, ``/connected_clients``) and proves who it
is through one check (``entry``, ``rwt_protocol.credentials``), and its session
runs on the same graph through the same pump (D22), so a TCP client, a WebSocket
client, a Foxglove client and an HTTP request see each other's topics and
services. Its settings are ``ServerConfig`` (config.py), rosauth's check of the
``auth`` op is rosauth.py's. The server also keeps the latched
``/client_count`` and ``/connected_clients`` topics that rosbridge publishes
(D14), from node ``/rosbridge_websocket``, offers rosapi (REF §7.1) from node
``/rosapi`` (listing only what the access rules let a client see) and
tf2_web_republisher (REF §7.3) from node ``/tf2_web_republisher``, enforces
``max_connections``, and stops gracefully: the listeners close, every session
releases what it holds (so callers waiting on it are answered), WebSocket
clients get close code 1001, and after ``shutdown_grace_s`` whatever is left is
cut.
"""

from __future__ import annotations

import asyncio
import errno
import itertools
import logging
import math
import socket
import ssl
import sys
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine, Iterable
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import replace
from typing import TYPE_CHECKING

import anyio
from anyio.abc import (
    ByteStream,
    SocketAttribute,
    SocketListener,
    SocketStream,
    TaskGroup,
    TaskStatus,
)
from anyio.streams.stapled import MultiListener
from anyio.streams.tls import TLSStream

from rwt_console.site import ConsoleSite, console_for
from rwt_graph.graph import Graph
from rwt_graph.ratelog import EpisodeLog
from rwt_graph.rosapi import Rosapi, VisibilityFor, install_rosapi
from rwt_graph.simtime import follow_clock
from rwt_graph.tasks import start_soon
from rwt_graph.tf.loop import install_tf_republisher
from rwt_graph.types.convert import time_value
from rwt_graph.visibility import Visibility
from rwt_protocol.credentials import EntryAuth
from rwt_protocol.errors import ConfigError, RwtError
from rwt_protocol.framing.fragments import FragmentBudget
from rwt_protocol.ops.base import Compression
from rwt_protocol.runtime.flow import FlowControl, HostCoolDowns
from rwt_protocol.runtime.memory import MemoryBudget
from rwt_protocol.runtime.request import SessionRequest
from rwt_protocol.server.session import CloseCode, Session, SessionConfig
from rwt_protocol.shortcuts import switched_off

from .admission.arrival import Admission, Ticket
from .admission.pending import PendingRequests, PendingSocket, current_socket, serve_socket
from .admission.shares import HostPrefixes, HostShares, address_of
from .config import ServerConfig
from .deadman import run_deadman
from .frontends import FrontEnd, FrontEnds
from .frontends_registry import HTTP_FRONTENDS, SOCKET_FRONTENDS
from .gates import InboundBatch, OutboundHold
from .host import Admitted, Features, HostSettings, ServedFrontEnd
from .listen import ListenError
from .memory import MemoryConnection, memory_pair
from .process.fdlimit import REFUSING_SOCKETS, default_max_connections
from .pump import ConnectionPump, run_connection
from .rosauth import rosauth_authenticator, url_authenticator
from .rosbridge import rosbridge_frontend
from .stdio import StdioChannel
from .tcp import serve_tcp_connection
from .udp.auth import UdpAuth
from .udp.transport import serve_udp
from .websocket import serve_websocket_connection

if TYPE_CHECKING:
    from pathlib import Path

    from rwt_graph.calls import Soon, Spawner
    from rwt_graph.local import LocalPublisher
    from rwt_graph.tf import TFRepublisher
    from rwt_protocol.auth import Authenticator
    from rwt_protocol.runtime.access import AccessPolicy
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.rules import ClientRules

    from .holding import Held
    from .http.endpoint import HttpEndpoint
    from .workers.placement import Placement

__all__ = [
    "SERVER_NODE",
    "GraphServer",
    "RosbridgeServer",
    "ServerConfig",
    "rosauth_authenticator",
    "spawner_for",
    "visibility_of",
]

logger = logging.getLogger("rwt.server")

# the listeners as a ListenError names them (a front end's own port: "WebSocket (foxglove)")
_LISTENER_NAMES = {"websocket": "WebSocket", "tcp": "TCP"}

_TLS_FAILURES = (ssl.SSLError, OSError, anyio.BrokenResourceError, anyio.EndOfStream)

_ACCEPT_BACKOFF_S = 0.1
"""First pause of the accept loop after ``accept()`` failed (EMFILE...); doubles per failure."""
_ACCEPT_BACKOFF_MAX_S = 1.0
"""Longest pause of the accept loop between two failed ``accept()`` calls."""

_LOCAL = frozenset({"stdio", "memory"})
"""Transports whose connections do not count against a host's share (every other does)."""

#: The node of the server's own publishers, as rosbridge names it.
SERVER_NODE = "/rosbridge_websocket"


Runner = Callable[[TaskGroup], Coroutine[object, object, None]]


class GraphServer:
    """Serves one graph over every configured transport, in every registered protocol.

    The protocols are the registry's front ends (``frontends_registry``):
    rosbridge by default, Foxglove's by subprotocol, the HTTP front ends
    (``/version``, WebRTC, MCP, the HTTP API) by path. ``RosbridgeServer`` is the
    same class, under its first name.

    Args:
        graph: the graph to serve; a new ROS 2 graph by default.
        config: server settings.
        authenticator: admits or refuses each connection's ``auth`` op (D23);
            it receives the op and the peer address and returns True to admit.
            It overrides ``config.session.authenticator``. See
            ``rosauth_authenticator`` for rosauth's MAC check.

    Raises:
        ConfigError: ``config.host_prefix_v4`` or ``host_prefix_v6`` is outside
            its address's width (``admission.shares.HostPrefixes``); an HTTP front end's
            options are not of its type.
        RulesError: ``config.safety`` does not fit the graph's types (a ``ConfigError``).
        ImportError: ``config.webrtc`` is set but aiortc is not (``rwt-rosbridge[webrtc]``);
            ``config.mcp`` is set but the MCP SDK is not (``rwt-rosbridge[mcp]``).
    """

    session_class: type[Session] = Session
    """What each connection's session is (a subclass can change how it reports, for tests)."""

    def __init__(
        self,
        graph: Graph | None = None,
        config: ServerConfig | None = None,
        *,
        authenticator: Authenticator | None = None,
    ) -> None:
        self.config = config or ServerConfig()
        # a bad prefix is refused (ConfigError) before the graph is touched
        self.host_prefixes = HostPrefixes(self.config.host_prefix_v4, self.config.host_prefix_v6)
        """What names a peer's host for the host shares (``--host-prefix-v4``, ``-v6``)."""
        self.graph = graph or Graph()
        if self.config.safety is not None and self.graph.safety is None:
            self.graph.use_safety(self.config.safety)  # RulesError: they do not fit its types
        # one flow control for the connections and the links (it keeps the hosts' cool-downs);
        # links' deliveries are held back as readers are
        self.flow: FlowControl[Held] = FlowControl(
            self.config.session.hold_budget_s, HostCoolDowns(self.host_prefixes)
        )
        self.graph.port.inflow = InboundBatch(self.flow)
        # one order of first input for its connections, on its loop (admission/arrival.py)
        self.admission = Admission()
        # one size limit for every transport and for reassembly: the session's is set here
        session_config = replace(self.config.session, max_message_size=self.config.max_message_size)
        if authenticator is not None:
            session_config = replace(session_config, authenticator=authenticator)
        self.session_config = session_config
        # the web console of the WebSocket port, or None; the config then names it
        self.console, self.config = self._console_site()
        self._hold_graph(session_config.send_buffer_limit)
        # one budget for what every connection makes the server hold (D44); incomplete
        # messages draw from it within their own
        self.memory = MemoryBudget(self.config.memory_budget)
        self.fragment_budget = FragmentBudget(self.config.max_fragment_memory, self.memory)
        self.pending = PendingRequests(
            self.fragment_budget, self.host_prefixes, self.config.max_connections_per_host
        )
        """What sockets not yet admitted hold, by host (D58): their requests' bytes within
        the budgets above and the host's share, the requests each host reads at once."""
        self.entry = self._entry_auth(session_config.authenticator)
        """The one check of every way in (``rwt_protocol.credentials``): each front end's
        ``AuthMode`` and what its client presented."""
        # the registry's protocols of the WebSocket listeners: rosbridge by default, the
        # others by subprotocol, on the WebSocket port and on ports of their own
        self.frontends, self._own_ports = self._socket_frontends()
        # stream connections (not stdio, not in-process) close when idle
        self._stream_session_config = replace(
            session_config, idle_timeout_s=self.config.idle_timeout_s or None
        )
        self._shares = HostShares(self.config.max_connections_per_host)
        self._hosts: dict[str, str] = {}  # client id -> its host, for the shares
        # sessions shared from the first (open_session's share_from_first), per transport and
        # host (D40: MCP sessions; D59: the HTTP API's event streams)
        self._first_shares: dict[str, HostShares] = {}
        self._first_hosts: dict[str, tuple[str, str]] = {}  # client id -> transport, host
        self._extra_slots = 0  # slots held without a session of their own (take_slot, admit)
        self._refusals = EpisodeLog(logger)
        self.sessions: dict[str, ServerSession] = {}
        self.urls: dict[str, str] = {}
        self._ids = itertools.count(1)
        self._connected: dict[str, dict[str, object]] = {}
        self._limit = self.config.max_connections  # resolved from RLIMIT_NOFILE in serve
        self._handshaking = 0  # accepted stream sockets without a session yet
        self._slot_freed: anyio.Event | None = None  # the accept loops wait on it when full
        self._clients_changed: anyio.Event | None = None  # None: publish at once (not serving)
        self._client_count = _latched(self.graph, "/client_count", "std_msgs/msg/Int32")
        self._connected_clients = _latched(
            self.graph, "/connected_clients", "rosbridge_msgs/msg/ConnectedClients"
        )
        self._publish_clients()
        self.rosapi, self.tf = self._install_helpers()
        self.endpoints: dict[str, HttpEndpoint] = {}
        """The HTTP front ends served on the WebSocket port, by their registry name
        (``version``, ``webrtc``, ``mcp``, ``http``), in the order they claim requests."""
        for frontend in HTTP_FRONTENDS:
            options = frontend.options_in(self.config)
            if options is not None:
                self.endpoints[frontend.name] = frontend.make_endpoint(self, options)
        self._stop_requested = False
        self._stop: anyio.Event | None = None
        self._all_closed: anyio.Event | None = None
        self._stopping = False

    def _hold_graph(self, send_buffer_limit: int) -> None:
        """Bind the graph's publishers and stores to this server's limits."""
        # a link's queue for the other middleware holds publishers back as a subscriber does
        self.graph.port.outflow = OutboundHold(self.flow)
        # a topic's transient-local store fits a late subscriber's queue, and all of
        # them the server's memory budget (D63)
        self.graph.port.max_store_bytes = send_buffer_limit
        self.graph.port.stores.limit = self.config.memory_budget

    def _entry_auth(self, authenticator: Authenticator | None) -> EntryAuth:
        """The one entry check for ``authenticator`` and ``ServerConfig.bearer_token``.

        URL tokens are checked under their own MAC where rosauth's check binds
        connections (``rosauth.url_authenticator``, D33).
        """
        url = None if authenticator is None else url_authenticator(authenticator)
        return EntryAuth(authenticator is not None, authenticator, url, self.config.bearer_token)

    def _socket_frontends(self) -> tuple[FrontEnds, dict[str, tuple[int, FrontEnds]]]:
        """The WebSocket listeners' front ends, from the registry.

        Returns:
            Those of the WebSocket port (rosbridge by default, the registered ones
            the configuration puts there), and, by name, each registered front end's
            own port with the front ends that answer there (``--foxglove-port``).
        """
        on_port: list[FrontEnd] = []
        own: dict[str, tuple[int, FrontEnds]] = {}
        for entry in SOCKET_FRONTENDS:
            frontend = entry.make(self, entry.options(self.config))
            if entry.on_port(self.config):
                on_port.append(frontend)
            port = entry.own_port(self.config)
            if port is not None:
                own[entry.name] = (port, FrontEnds(None, [frontend]))
        return FrontEnds(rosbridge_frontend(self._rosbridge_session), on_port), own

    def _install_helpers(self) -> tuple[Rosapi | None, TFRepublisher | None]:
        """The helpers: rosapi (showing what the access rules let one see), TF republisher."""
        rosapi = None
        if self.config.rosapi:
            visibility = self.config.rosapi_visibility
            access = self.session_config.access
            if visibility is None and access.restricted:
                visibility = visibility_of(access)
            rosapi = install_rosapi(self.graph, visibility=visibility)
        tf = install_tf_republisher(self.graph) if self.config.tf else None
        return rosapi, tf

    def _console_site(self) -> tuple[ConsoleSite | None, ServerConfig]:
        """``WebSocketOptions.console`` made a site, and the config with it.

        True builds it as ``rwt serve`` does (``console_for``) from the server's
        settings; False and None are off; a ``ConsoleSite`` is kept.
        """
        config = self.config
        wanted = config.websocket.console
        site: ConsoleSite | None = None
        if isinstance(wanted, ConsoleSite):
            site = wanted
        elif wanted:
            site = console_for(
                None,
                config.websocket.allowed_origins,
                config.websocket.url_path,
                tls=config.certfile is not None,
                auth=self.session_config.authenticator is not None,
                foxglove=config.foxglove.on_rosbridge_port,
            )
        return site, replace(config, websocket=replace(config.websocket, console=site))

    def features(self) -> Features:
        """What this server offers, for ``GET /version``'s ``rwt`` object (D49).

        From the configuration and the registry's front ends as they are served now
        (one added by ``add_frontend`` too); nothing secret.
        """
        config, tls = self.config, self.config.certfile is not None
        transports = [
            name
            for name, on in (
                ("wss" if tls else "ws", config.port is not None),
                ("tcp+tls" if tls else "tcp", config.tcp_port is not None),
                ("udp", config.udp_port is not None),
                ("stdio", config.stdio),
            )
            if on
        ]
        served = [each for each in HTTP_FRONTENDS if each.name in self.endpoints]
        transports += [each.transport for each in served if each.transport is not None]
        required = self.entry.required
        frontends = [
            ServedFrontEnd(
                each.name,
                each.subprotocols,
                (*each.labels, *each.lossy_labels),
                auth=each.auth.value if required else "none",
            )
            for each in self.frontends.every
        ]
        frontends += [
            ServedFrontEnd(
                each.name, paths=each.paths, auth=each.auth.value if required else "none"
            )
            for each in served
        ]
        auth = "none"
        if required:
            auth = "op-bound" if self.session_config.auth_challenge else "op"
        return Features(
            transports=tuple(transports),
            encodings=tuple(each.value for each in Compression),
            subprotocols=tuple(n for each in self.frontends.others for n in each.subprotocols),
            frontends=tuple(frontends),
            auth=auth,
            safety=self.graph.safety is not None,
        )

    def add_frontend(self, frontend: FrontEnd) -> None:
        """Speak one more protocol on the WebSocket port, chosen by its subprotocols.

        Its data-channel labels (``FrontEnd.labels``) select it on WebRTC too. It
        gets the server's admission, per-client rules and flow control as
        rosbridge and Foxglove do (docs/architecture.md, "How to add a protocol").
        Call it before ``serve``.
        """
        self.frontends = FrontEnds(self.frontends.default, [*self.frontends.others, frontend])

    # ---- running --------------------------------------------------------------

    async def serve(
        self,
        *,
        task_status: TaskStatus[str] = anyio.TASK_STATUS_IGNORED,
        on_listening: Callable[[str], None] | None = None,
    ) -> None:
        """Run every configured listener until ``stop()`` (graceful) or cancellation.

        Args:
            task_status: receives the first listener's URL (the WebSocket one,
                ``ws://HOST:PORT``, when there is one) for ``TaskGroup.start``;
                ``urls`` has them all by then.
            on_listening: called with each listener's URL, in order.

        Raises:
            ListenError: a listener cannot bind its address (also an ``OSError``);
                the text names the listener, the address and why:
                ``cannot listen for TCP on 127.0.0.1:9091: address already in use``.
            ssl.SSLError: the certificate or key cannot be loaded.
        """
        self._stop = anyio.Event()
        if self._stop_requested:
            self._stop.set()
        if self._limit is None:
            self._limit = default_max_connections()
        logger.info("event=max_connections limit=%s", self._limit)
        off = switched_off()
        if off:  # a slower server than the benchmarks measured: say so once
            logger.info("event=shortcuts_off names=%s", ",".join(sorted(off)))
        async with AsyncExitStack() as stack:
            if self.config.use_sim_time:  # before any client: each is told of server time
                stack.enter_context(follow_clock(self.graph))
            runners = await self._open_listeners(stack)
            for url in self.urls.values():
                logger.info("event=listening url=%s", url)
                if on_listening is not None:
                    on_listening(url)
            task_status.started(next(iter(self.urls.values()), ""))
            async with anyio.create_task_group() as connections:
                try:
                    # async in-process handlers run in the connections' task group
                    with self.graph.port.serving(spawner_for(connections), loop_soon()):
                        self._clients_changed = anyio.Event()
                        connections.start_soon(self._publish_clients_loop)
                        if self.graph.safety is not None:  # the dead-man's timer (docs/safety.md)
                            connections.start_soon(run_deadman, self.graph.safety)
                        for endpoint in self.endpoints.values():
                            endpoint.bind(connections)
                        async with anyio.create_task_group() as accepting:
                            for runner in runners:
                                accepting.start_soon(runner, connections)
                            await self._stop.wait()
                            accepting.cancel_scope.cancel()
                        await self._shutdown(connections)
                finally:
                    for endpoint in self.endpoints.values():
                        endpoint.bind(None)
                    self._clients_changed = None
                    self._publish_clients()  # the final state, latched

    @property
    def stop_requested(self) -> bool:
        """Whether ``stop`` was called: ``rwt serve`` stops at once on a second signal."""
        return self._stop_requested

    def stop(self) -> None:
        """Stop serving gracefully (SIGTERM/SIGINT in ``rwt serve``); ``serve`` then returns."""
        self._stop_requested = True
        if self._stop is not None:
            self._stop.set()

    async def _shutdown(self, connections: TaskGroup) -> None:
        self._stopping = True
        sessions = list(self.sessions.values())
        logger.info("event=shutdown sessions=%d", len(sessions))
        self.graph.port.fail_pending("server shutting down")  # while callers can still read
        for endpoint in self.endpoints.values():  # nothing new; what is not running yet goes
            endpoint.bind(None)
        for session in sessions:
            session.begin_shutdown()
        for session in sessions:
            session.request_close(CloseCode.GOING_AWAY, "server shutting down")
        self._all_closed = anyio.Event()
        if not self.sessions:
            self._all_closed.set()
        with anyio.move_on_after(self.config.shutdown_grace_s):
            await self._all_closed.wait()
        connections.cancel_scope.cancel()

    async def _open_listeners(self, stack: AsyncExitStack) -> list[Runner]:
        config = self.config
        tls = _tls_context(config.certfile, config.keyfile)
        runners: list[Runner] = []
        if config.port is not None:
            websocket = self._websocket_handler(None, self.endpoints.values())
            runners.append(
                await self._stream_listener(stack, config.port, tls, "websocket", websocket)
            )
            if config.placement is not None and tls is None:  # TLS connections stay
                runners.append(self._placed_runner(config.placement))
        for name, (port, frontends) in self._own_ports.items():  # a front end's own port
            runners.append(
                await self._stream_listener(
                    stack, port, tls, name, self._websocket_handler(frontends)
                )
            )
        if config.tcp_port is not None:
            runners.append(
                await self._stream_listener(stack, config.tcp_port, tls, "tcp", self._handle_tcp)
            )
        if config.udp_port is not None:
            try:
                sock = await anyio.create_udp_socket(
                    local_host=config.host, local_port=config.udp_port
                )
            except OSError as exc:
                raise ListenError("UDP", config.host, config.udp_port, exc) from exc
            await stack.enter_async_context(sock)
            port = sock.extra(SocketAttribute.local_port)
            self.urls["udp"] = f"udp://{_url_host(config.host)}:{port}"

            async def run_udp(connections: TaskGroup) -> None:
                required = self.session_config.authenticator is not None
                auth = UdpAuth(required, required and self.session_config.auth_challenge)
                work = serve_udp(
                    sock,
                    self,
                    config.udp,
                    config.max_message_size,
                    self.host_prefixes,
                    auth=auth,
                )
                await _contained("udp endpoint", work)

            runners.append(run_udp)
        if config.stdio:
            self.urls["stdio"] = "stdio:"
            runners.append(self._run_stdio)
        return runners

    async def _stream_listener(
        self,
        stack: AsyncExitStack,
        port: int,
        tls: ssl.SSLContext | None,
        kind: str,
        handler: Callable[[ByteStream], Awaitable[None]],
    ) -> Runner:
        """Listen on ``port`` for ``kind`` (``websocket``, ``tcp``, a front end's own port).

        A kind whose sockets this process inherited (``ServerConfig.listen_fds``)
        accepts from them instead.
        """
        try:
            inherited = self.config.listen_fds.get(kind)
            if inherited:
                listener = MultiListener([await _inherited_listener(fd) for fd in inherited])
            else:
                listener = await anyio.create_tcp_listener(
                    local_host=self.config.host, local_port=port, reuse_port=self.config.reuse_port
                )
        except OSError as exc:
            name = _LISTENER_NAMES.get(kind, f"WebSocket ({kind})")
            raise ListenError(name, self.config.host, port, exc) from exc
        await stack.enter_async_context(listener)
        bound = listener.extra(SocketAttribute.local_port)
        scheme = ("tcp", "tcp+tls") if kind == "tcp" else ("ws", "wss")
        self.urls[kind] = f"{scheme[tls is not None]}://{_url_host(self.config.host)}:{bound}"

        async def run(connections: TaskGroup) -> None:
            async with anyio.create_task_group() as sockets:  # one per address family
                for each in listener.listeners:
                    assert isinstance(each, SocketListener)  # what create_tcp_listener makes
                    sockets.start_soon(self._accept_loop, each, handler, tls, connections)

        return run

    async def _accept_loop(
        self,
        listener: SocketListener,
        handler: Callable[[ByteStream], Awaitable[None]],
        tls: ssl.SSLContext | None,
        connections: TaskGroup,
    ) -> None:
        """Accept connections until cancelled; never ends for a failed ``accept()``.

        Out of descriptors (EMFILE, ENFILE) or kernel memory (ENOBUFS, ENOMEM),
        ``accept()`` fails while the connection waits in the backlog: the loop
        pauses (``_ACCEPT_BACKOFF_S`` doubling up to ``_ACCEPT_BACKOFF_MAX_S``),
        logs ``event=accept_backoff`` once per episode, and serves the existing
        connections meanwhile. It also stops accepting while ``max_connections``
        plus ``REFUSING_SOCKETS`` sockets are held (docs/limits.md).
        """
        delay = 0.0
        raw = listener.extra(SocketAttribute.raw_socket)
        while True:
            await self._accept_slot()
            try:
                sock = await _accept(raw)
            except OSError as exc:
                if not delay:
                    logger.warning(
                        "event=accept_backoff errno=%s reason=%r connections=%d handshaking=%d",
                        errno.errorcode.get(exc.errno or 0, exc.errno),
                        exc.strerror or str(exc),
                        len(self.sessions),
                        self._handshaking,
                    )
                delay = min(_ACCEPT_BACKOFF_MAX_S, delay * 2 if delay else _ACCEPT_BACKOFF_S)
                await anyio.sleep(delay)
                continue
            if delay:
                logger.info("event=accept_resumed")
                delay = 0.0
            self._handshaking += 1
            # Plain TCP: the client may have sent already; handle that first (admission/arrival.py).
            # TLS waits for the peer's handshake first, WebSocket for its request.
            ticket = self.admission.hold() if handler == self._handle_tcp and tls is None else None
            connections.start_soon(self._serve_socket, sock, handler, tls, ticket)

    async def _accept_slot(self) -> None:
        """Wait while the server holds all the sockets it may (slots and handshakes)."""
        while (limit := self._limit) is not None and (
            self.slots_taken + self._handshaking >= limit + REFUSING_SOCKETS
        ):
            if self._slot_freed is None or self._slot_freed.is_set():
                self._slot_freed = anyio.Event()  # one for every listener waiting
            await self._slot_freed.wait()

    def _free_slot(self) -> None:
        if self._slot_freed is not None:
            self._slot_freed.set()

    @property
    def slots_taken(self) -> int:
        """Connection slots held (``--max-connections``).

        One per session, one per ticket without a session yet (``admit``: a WebRTC
        peer before its data channel, a video-only one), and the sockets' own
        (``take_slot``).
        """
        return len(self.sessions) + self._extra_slots

    async def _serve_socket(
        self,
        sock: socket.socket,
        handler: Callable[[ByteStream], Awaitable[None]],
        tls: ssl.SSLContext | None,
        ticket: Ticket | None = None,
    ) -> None:
        """Run one accepted socket: handshakes within the timeout, then its session.

        ``open_session`` lifts the handshake deadline; a bug ends this socket only.
        ``ticket``: held from accept until the reader handled the input already
        there (admission/arrival.py).
        """
        pending: PendingSocket | None = None
        if ticket is not None:
            ticket.serve()
        stream: SocketStream | None = None
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # as anyio's accept does
            stream = await SocketStream.from_socket(sock)
            peer = _peer(stream)
            # what it holds until admitted (D58); this task's: open_session finds it
            pending = self.pending.socket(peer)
            serve_socket(pending)
            with anyio.CancelScope(
                deadline=anyio.current_time() + self.config.handshake_timeout_s
            ) as pending.scope:
                await _contained(f"connection from {peer}", self._run_socket(stream, handler, tls))
            if pending.scope.cancelled_caught and not pending.admitted:
                logger.info("event=handshake_timeout peer=%s", peer)
        except OSError as exc:  # the peer left before its socket was set up
            logger.info("event=accept_failed reason=%r", exc.strerror or str(exc))
        finally:
            if ticket is not None:
                ticket.release()
            if stream is not None:
                await anyio.aclose_forcefully(stream)
            else:
                sock.close()
            if pending is not None:
                pending.release()
            if pending is None or not pending.admitted:
                self._handshaking -= 1
                self._free_slot()

    @staticmethod
    async def _run_socket(
        stream: SocketStream,
        handler: Callable[[ByteStream], Awaitable[None]],
        tls: ssl.SSLContext | None,
    ) -> None:
        served: ByteStream = stream
        if tls is not None:
            try:
                served = await TLSStream.wrap(
                    stream, server_side=True, ssl_context=tls, standard_compatible=False
                )
            except _TLS_FAILURES as exc:
                reason = str(exc) or type(exc).__name__
                logger.info("event=tls_handshake_failed peer=%s reason=%r", _peer(stream), reason)
                return
        await handler(served)

    # ---- connections ------------------------------------------------------------

    def _websocket_handler(
        self,
        frontends: FrontEnds | None,
        http: Iterable[HttpEndpoint] = (),
        resumed: bytes | None = None,
    ) -> Callable[[ByteStream], Awaitable[None]]:
        """The connections of a WebSocket listener speaking ``frontends``, answering ``http``.

        None: the WebSocket port's, read at each connection (``add_frontend``).
        ``resumed``: a connection another worker handed here with the bytes it read
        (workers/placement.py); it is not moved again.
        """
        endpoints = list(http)

        # the WebSocket port's rosbridge connections may move by topic (workers/placement.py)
        placement = self.config.placement if frontends is None and resumed is None else None

        async def handle(stream: ByteStream) -> None:
            await serve_websocket_connection(
                stream,
                _peer(stream),
                self,
                self.config.websocket,
                self.config.max_message_size,
                self.fragment_budget,
                frontends=self.frontends if frontends is None else frontends,
                entry=self.entry,
                http=endpoints,
                placement=placement,
                resumed=resumed,
            )

        return handle

    def _placed_runner(self, placement: Placement) -> Runner:
        """Serve the connections other workers hand by their first topic here (workers/placement).

        Each is one more socket in handshake, as an accepted one is, and runs as the
        WebSocket port's connections do, reading first what the other worker read.
        """

        async def run(connections: TaskGroup) -> None:
            def take(sock: socket.socket, record: bytes) -> None:
                self._handshaking += 1
                handle = self._websocket_handler(None, resumed=record)
                connections.start_soon(self._serve_socket, sock, handle, None)

            try:
                await placement.serve(take)
            except OSError as exc:  # the state folder is gone: connections stay where they land
                logger.warning("event=placement_unavailable error=%r", exc)

        return run

    async def _handle_tcp(self, stream: ByteStream) -> None:
        peer = _peer(stream)
        transport = "tls" if self.config.certfile is not None else "tcp"
        # TLS: from the end of its handshake the client may send; that goes first
        # (admission/arrival.py). Plain TCP holds its ticket from accept.
        ticket = self.admission.hold() if transport == "tls" else None
        if ticket is not None:
            ticket.serve()
        try:
            await serve_tcp_connection(
                stream, peer, self, self.config.max_message_size, transport, self.fragment_budget
            )
        finally:
            if ticket is not None:
                ticket.release()

    async def _run_stdio(self, connections: TaskGroup) -> None:
        read_fd, write_fd = self.config.stdio_fds or (sys.stdin.fileno(), sys.stdout.fileno())
        channel = StdioChannel(read_fd, write_fd, self.config.max_message_size)
        pump = ConnectionPump(channel, self.flow, self.admission)
        session = self.open_session("stdio", "stdio", pump.wake)
        if session is None:
            return

        async def run() -> None:
            try:
                with channel:
                    await _contained("stdio session", run_connection(pump, session))
            finally:
                self.stop()  # the session ended (the parent's input, or a bug): nothing left

        connections.start_soon(run)

    @asynccontextmanager
    async def connect_memory(self) -> AsyncIterator[MemoryConnection]:
        """Open an in-process client connection (same gates and limits as a socket).

        Yields:
            the client's end; the connection closes when the block exits.

        Raises:
            RwtError: the server is full or stopping.
        """
        channel, client = memory_pair()
        pump = ConnectionPump(channel, self.flow, self.admission)
        session = self.open_session("memory", "memory", pump.wake)
        if session is None:
            raise RwtError("too many connections")
        async with anyio.create_task_group() as tg:
            tg.start_soon(run_connection, pump, session)
            try:
                yield client
            finally:
                await client.aclose()

    def open_session(
        self,
        transport: str,
        peer: str,
        on_output: Callable[[], None],
        *,
        frontend: FrontEnd | None = None,
        auth_nonce: str | None = None,
        authenticated: bool = False,
        ticket: Admitted | None = None,
        share_from_first: bool = False,
    ) -> ServerSession | None:
        """Admit a new connection and make its session on this server's graph.

        Admission (``admit``) is the same for every protocol; the front end only
        makes the session, under the per-client rules of its transport.

        Args:
            transport: ``ws``, ``tcp``, ``tls``, ``udp``, ``webrtc``, ``mcp``, ``stdio`` or
                ``memory``;
                the client id is ``<transport>:<peer>#<n>``.
            peer: the peer's address.
            on_output: the pump's wake-up.
            frontend: the protocol the connection speaks; None: rosbridge.
            auth_nonce: the connection's auth challenge, when the transport sent
                it (UDP, with ``--auth-bind-connection``); None: the session
                makes and sends one if it needs one.
            authenticated: the transport already admitted the connection with
                the authenticator (a URL token).
            ticket: the connection was admitted already (``admit``): its session
                takes the ticket's slot and id, and ``transport`` and ``peer`` are
                the ticket's.
            share_from_first: its host's share of such sessions of ``transport``
                applies from the first, not only past
                ``admission.shares.SHARES_FROM`` of the slots: a session that holds no
                socket of its own (MCP's, D40), which a ``--max-connections`` derived
                from the descriptors would bound late, or that costs the loop
                for as long as it lasts (the HTTP API's event streams, D59).

        Returns:
            The session, or None when ``max_connections`` is reached (sockets
            still in their handshake count), the peer's host holds its share (with
            ``share_from_first``, its share of those sessions), or the server is
            stopping.
        """
        if ticket is None:
            admitted = self._admit(transport, peer, from_first=share_from_first)
            if admitted is None:
                return None
            client_id, host, address = admitted
        elif not self._redeem(ticket):
            return None
        else:
            client_id, host, address = ticket.client_id, ticket.host, ticket.address
            transport, peer = ticket.transport, ticket.peer
        request = SessionRequest(
            self.graph.port,
            client_id,
            transport,
            peer,
            self._session_config_for(transport),
            on_output,
            self._session_closed,
            auth_nonce,
            authenticated,
            self.memory,
        )
        made = frontend or self.frontends.default or rosbridge_frontend(self._rosbridge_session)
        session = made.make_session(request)
        self.sessions[client_id] = session
        envelope = self.graph.safety
        if envelope is not None:  # its audit names the front end (docs/safety.md)
            envelope.connected(client_id, made.name)
        if host is not None:
            self._shares.add(host)
            self._hosts[client_id] = host
            if share_from_first:
                self._first_share(transport).add(host)
                self._first_hosts[client_id] = (transport, host)
        self.graph.nodes.attach(client_id, host=address)
        self._connected[client_id] = {
            "ip_address": address,
            "connection_time": time_value(self.graph.clock.wall(), self.graph.registry.dialect),
        }
        self._clients_churned()
        return session

    def admit(self, transport: str, peer: str) -> Admitted | None:
        """Admission without a session yet: a slot and the host's share, held by a ticket.

        The same admission as ``open_session``'s (``--max-connections``, the host
        shares, a socket's handshake deadline lifted), for a front end that makes
        its session later or never (a WebRTC peer before its data channel): the
        ticket holds a slot until ``open_session(ticket=...)`` makes the session
        or ``release`` gives it back.

        Returns:
            The ticket; None when ``open_session`` would refuse (full, stopping,
            the host holds its share).
        """
        admitted = self._admit(transport, peer)
        if admitted is None:
            return None
        client_id, host, address = admitted
        self._extra_slots += 1
        if host is not None:
            self._shares.add(host)
        return Admitted(client_id, transport, peer, host, address)

    def release(self, ticket: Admitted) -> None:
        """Give back the slot of a ticket no session took (``admit``); idempotent."""
        if self._redeem(ticket):
            self._free_slot()

    def _redeem(self, ticket: Admitted) -> bool:
        """Take ``ticket``'s slot back from it once: whether it still held one."""
        if ticket.redeemed:
            return False
        ticket.redeemed = True
        self._extra_slots -= 1
        if ticket.host is not None:
            self._shares.remove(ticket.host)
        return True

    def join_socket(self) -> None:
        """The socket of this task carries a request of a connection admitted already.

        A front end whose connection spans requests on sockets of their own (an MCP
        session, Streamable HTTP) calls it once a request is known to belong to an
        admitted connection: its handshake deadline is lifted and it no longer counts
        as a socket in its handshake; the slots of its connection cover it, or one it
        took (``take_slot``; docs/limits.md, D40).
        """
        pending = current_socket()
        if pending is not None:
            pending.admit()
            pending.scope.deadline = math.inf
            self._handshaking -= 1
            self._free_slot()

    def take_slot(self, transport: str, peer: str) -> str | None:
        """Take a connection slot without a session, for a socket a session's request holds.

        An MCP session's requests each hold a socket (Streamable HTTP), which its
        own slot cannot cover (D40): each takes a slot as a connection does,
        within ``max_connections`` and the host share of ``peer``. The socket of
        this task, if still in its handshake, does not count against it.

        Args:
            transport: the session's transport (``mcp``), for the log.
            peer: the address the socket came from (``HOST:PORT``).

        Returns:
            The host it counts against: give it back with ``give_slot`` once the
            socket is closed. None: refused (the server is full or stopping, or
            the host holds its share), as ``open_session`` refuses a connection.
        """
        checked = self._check_slot(transport, peer, current_socket() is not None)
        if checked is None:
            return None
        host = checked[0] or address_of(peer)
        self._extra_slots += 1
        self._shares.add(host)
        return host

    def give_slot(self, host: str) -> None:
        """Give back a slot ``take_slot`` gave for ``host``."""
        self._extra_slots -= 1
        self._shares.remove(host)
        self._free_slot()

    def _admit(
        self, transport: str, peer: str, *, from_first: bool = False
    ) -> tuple[str, str | None, str] | None:
        """Admission: a slot (``--max-connections``) and the host's share, or None.

        Returns the new client id, the peer's host for the shares (None for stdio
        and in-process connections) and its address. An admitted socket's
        handshake deadline is lifted. ``from_first``: the host's share of such
        sessions applies from the first (D40, ``open_session``).
        """
        pending = current_socket()  # None: a task of an admitted connection, not a new one
        checked = self._check_slot(transport, peer, pending is not None)
        if checked is None:
            return None
        host, address = checked
        if host is not None and from_first:
            shares = self._first_share(transport)
            held = shares.held(host)
            if held >= shares.share:  # D40, D59: from the first session
                self._refused(peer, host, f"host share of {transport} sessions", held, shares.share)
                return None
        if pending is not None:  # the socket's handshake is over: no deadline, a session now
            pending.admit()
            pending.scope.deadline = math.inf
            self._handshaking -= 1
        return f"{transport}:{peer}#{next(self._ids)}", host, address

    def _first_share(self, transport: str) -> HostShares:
        """The hosts' shares of ``transport``'s sessions counted from the first (D40, D59)."""
        shares = self._first_shares.get(transport)
        if shares is None:
            shares = HostShares(self.config.max_connections_per_host)
            self._first_shares[transport] = shares
        return shares

    def _check_slot(
        self, transport: str, peer: str, own_socket: bool
    ) -> tuple[str | None, str] | None:
        """Whether a slot is free for ``peer``: its host (None if not shared) and address.

        ``own_socket``: the socket of this task is in its handshake and is what asks,
        so it does not count against itself. None: refused (full, stopping, the
        host holds its share; a share refusal is logged once per episode).
        """
        others = self._handshaking - own_socket
        limit = self._limit
        taken = self.slots_taken + others
        if self._stopping or (limit is not None and taken >= limit):
            return None
        address = address_of(peer)
        host = self.host_prefixes.host(address) if transport not in _LOCAL else None
        if host is not None and limit is not None and not self._shares.admits(host, taken, limit):
            self._refused(peer, host, "host share", self._shares.held(host), self._shares.share)
            return None
        return host, address

    def _refused(self, peer: str, host: str, reason: str, held: int, share: int) -> None:
        """Log a refusal for a host's share, once per episode of that host and reason."""
        self._refusals.log(
            logging.WARNING,
            f"share:{host}" if reason == "host share" else f"share:{host}:{reason}",
            "event=refused peer=%s host=%s reason=%r held=%d share=%d",
            peer,
            host,
            reason,
            held,
            share,
        )

    @property
    def settings(self) -> HostSettings:
        """What its front ends read of its settings (``host.FrontEndHost``)."""
        return _settings_of(self.config, self.session_config)

    def _session_config_for(self, transport: str) -> SessionConfig:
        """The per-client settings of a connection on ``transport``.

        Stream connections (``ws``, ``tcp``, ``tls``, ``webrtc``) and MCP sessions
        close when idle (``--idle-timeout``; an MCP session's input is its requests,
        D40); the others (stdio, in-process, UDP with its own rule, an HTTP request)
        never do.
        """
        stream = transport in ("ws", "tcp", "tls", "webrtc", "mcp")
        return self._stream_session_config if stream else self.session_config

    @property
    def rules(self) -> ClientRules:
        """The per-client rules of every protocol (``ServerConfig.session``'s ``ClientRules``)."""
        return self.session_config

    def _rosbridge_session(self, request: SessionRequest) -> Session:
        """A rosbridge session (``session_class``) for an admitted connection.

        Its section is rosbridge's ``SessionConfig``, the server's, whose
        ``ClientRules`` part is the request's rules (``_session_config_for``).
        """
        return self.session_class(
            request.graph,
            request.client_id,
            config=self._session_config_for(request.transport),
            on_output=request.on_output,
            peer=request.peer,
            on_closed=request.on_closed,
            fragment_budget=self.fragment_budget,
            auth_nonce=request.auth_nonce,
            authenticated=request.authenticated,
            memory=request.memory,
        )

    def _session_closed(self, client_id: str) -> None:
        self.sessions.pop(client_id, None)
        host = self._hosts.pop(client_id, None)
        if host is not None:
            self._shares.remove(host)
        first = self._first_hosts.pop(client_id, None)
        if first is not None:
            self._first_share(first[0]).remove(first[1])
        self._connected.pop(client_id, None)
        self._free_slot()
        if not self.sessions and self._all_closed is not None:
            self._all_closed.set()
        self._clients_churned()

    def _clients_churned(self) -> None:
        """A connection came or went: publish the client topics, coalesced while serving."""
        if self.config.on_connections is not None:
            self.config.on_connections(len(self.sessions))
        if self._clients_changed is None:
            self._publish_clients()
        else:
            self._clients_changed.set()

    async def _publish_clients_loop(self) -> None:
        """Publish the client topics at most once per ``_clients_wait()``, the latest state.

        The first change after a quiet interval goes out at once; the ones during
        the interval after it are published together at its end. Each publish
        sends the whole list to every subscriber, so publishing per connection
        cost O(connections x subscribers) per change.
        """
        while self._clients_changed is not None:
            await self._clients_changed.wait()
            self._clients_changed = anyio.Event()
            try:
                self._publish_clients()
            except Exception:  # a bug here must not end the server's task group
                logger.exception("event=bug task=publish_clients")
            await anyio.sleep(self._clients_wait())

    def _clients_wait(self) -> float:
        """Seconds before the client topics go out again.

        ``clients_interval_s``, or longer while one publish sends more entries
        (clients x subscribers) than ``clients_fanout_per_s`` allows in it.
        """
        topic = self.graph.topics.get("/connected_clients")
        entries = len(self._connected) * (len(topic.subscribers) if topic is not None else 0)
        return max(self.config.clients_interval_s, entries / self.config.clients_fanout_per_s)

    def _publish_clients(self) -> None:
        """Publish ``/client_count`` and ``/connected_clients`` (D14), both latched."""
        if self._client_count is not None:
            self._client_count.publish({"data": len(self.sessions)})
        if self._connected_clients is not None:  # entries are built once, at connect
            self._connected_clients.publish({"clients": list(self._connected.values())})


RosbridgeServer = GraphServer
"""``GraphServer`` under its first name: the public API and the docs that use it stay valid."""


def spawner_for(tg: TaskGroup) -> Spawner:
    """A graph spawner running jobs in ``tg``; each job can be cancelled alone.

    It may be called from a plain event-loop callback (a link's hand-over), where
    anyio can make no cancel scope (``rwt_graph.tasks``): the job makes its own
    once it runs, and a cancel that comes first stops it there.
    """

    def spawn(job: Callable[[], Awaitable[None]]) -> Callable[[], None]:
        scope: anyio.CancelScope | None = None
        cancelled = False

        def cancel() -> None:
            nonlocal cancelled
            cancelled = True
            if scope is not None:
                scope.cancel()

        async def run() -> None:
            nonlocal scope
            if cancelled:  # before it ran
                return
            with anyio.CancelScope() as scope:
                try:
                    await job()
                except Exception:  # a bug in an in-process handler: never the server's end
                    logger.exception("event=bug in a spawned job; it is dropped")

        start_soon(tg, run)
        return cancel

    return spawn


def loop_soon() -> Soon | None:
    """The running event loop's ``call_soon``, which the graph's batched delivery uses.

    None off asyncio (and uvloop): the graph then delivers every message as it
    is published (docs/embedding.md, "Batched delivery").
    """
    try:
        return asyncio.get_running_loop().call_soon
    except RuntimeError:
        return None


@asynccontextmanager
async def running_handlers(graph: Graph) -> AsyncIterator[TaskGroup]:
    """A task group in which ``graph``'s async in-process handlers run, without a server.

    For code that drives a graph without serving it (tests, benchmarks): inside,
    async services and actions run as under ``GraphServer.serve``
    (``GraphCore.serving``). Yields the task group; cancel its scope to stop.
    """
    async with anyio.create_task_group() as tg:
        with graph.port.serving(spawner_for(tg), loop_soon()):
            yield tg


async def _contained(what: str, work: Awaitable[None]) -> None:
    """Await ``work``, containing any exception it raises.

    An exception (a bug: everything expected is handled where it happens) is
    logged once with its traceback instead of reaching the server's task group,
    which would end every connection (docs/limits.md). Cancellation passes.
    """
    try:
        await work
    except* Exception as group:
        logger.error("event=bug task=%r", what, exc_info=group.exceptions[0])


def _settings_of(config: ServerConfig, session: SessionConfig) -> HostSettings:
    """What a front end reads of ``config`` (``host.HostSettings``)."""
    return HostSettings(
        config.host,
        config.port,
        config.certfile is not None,
        config.websocket.allowed_origins,
        config.max_message_size,
        config.idle_timeout_s,
        session.compat,
    )


def _tls_context(certfile: Path | None, keyfile: Path | None) -> ssl.SSLContext | None:
    """A server TLS context from PEM files (rosbridge's ``certfile``/``keyfile``), or None.

    It issues no TLS 1.3 session tickets (``num_tickets = 0``), so a TLS 1.3
    client cannot resume a session and makes a full handshake each time (TLS 1.2
    resumes as before). OpenSSL sends the tickets just after the handshake, when a
    client that reads its socket in one thread while it writes in another
    (websockets' sync client, any client with a receive thread) has its reader
    take them in while it writes its upgrade request or first op.
    OpenSSL does not allow ``SSL_read`` and ``SSL_write`` on one connection at
    the same time (https://github.com/openssl/openssl/issues/20446) and Python's
    ``ssl`` does not serialise them: now and then (one connection in a few
    hundred) the client's bytes were lost without an error. A wss client waited
    for the upgrade answer until the handshake timeout closed the socket; a TLS
    client on TCP never had its first op answered. The same race in a
    client library: https://github.com/miguelgrinberg/python-engineio/issues/461.
    Without tickets the reader has nothing to read until the server answers.
    """
    if certfile is None and keyfile is None:
        return None
    if certfile is None:
        raise ConfigError("--keyfile needs --certfile")
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    context.load_cert_chain(certfile, keyfile)
    context.num_tickets = 0
    return context


async def _inherited_listener(fd: int) -> SocketListener:
    """A listener on the listening socket of descriptor ``fd``, inherited (non-blocking).

    Raises:
        OSError: ``fd`` is no socket of this process.
        ValueError: it is no bound stream socket.
    """
    sock = socket.socket(fileno=fd)
    sock.setblocking(False)  # the parent's is already: the flag is the shared file's
    return await SocketListener.from_socket(sock)


async def _accept(listener: socket.socket) -> socket.socket:
    """The next connection of ``listener``, taken in the loop turn that finds it ready.

    Not anyio's ``accept``, which sets the stream up before it returns: the
    server would learn of the connection only a few loop turns later, after
    the older connections' input that arrived meanwhile (admission/arrival.py).

    Raises:
        OSError: ``accept()`` failed (EMFILE, ENFILE, ENOBUFS, ENOMEM, ...).
    """
    while True:
        await anyio.wait_readable(listener)
        try:
            sock, _ = listener.accept()
        except BlockingIOError:  # taken by another process sharing the socket
            continue
        return sock


def _latched(graph: Graph, topic: str, type_name: str) -> LocalPublisher | None:
    try:
        return graph.create_publisher(topic, type_name, latch=True, node=SERVER_NODE, reserved=True)
    except RwtError as exc:  # a registry without the type: no such topic
        logger.warning("not publishing %s: %s", topic, exc.message)
        return None


def _peer(stream: ByteStream | SocketStream) -> str:
    address = stream.extra(SocketAttribute.remote_address, None)
    if isinstance(address, tuple):
        return f"{address[0]}:{address[1]}"
    return str(address) if address else "unknown"


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def visibility_of(policy: AccessPolicy) -> VisibilityFor:
    """What rosapi shows every client under ``policy``: only what it may use."""
    visibility = Visibility.of(policy)  # the rule Foxglove clients' listings follow too
    return lambda client: visibility
