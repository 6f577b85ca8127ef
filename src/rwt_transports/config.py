"""The server's settings: ``ServerConfig``, what ``rwt serve`` maps its options onto.

Names follow rosbridge's parameters where it has one. The per-connection rules are
``session`` (rosbridge's ``SessionConfig``, over every protocol's ``ClientRules``);
each front end's own options are a field of their own (``foxglove``, ``webrtc``,
``mcp``) or ``http_options`` by the registry's name (``frontends_registry``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from rwt_protocol.runtime.memory import DEFAULT_MEMORY_BUDGET
from rwt_protocol.server.session import SessionConfig

from .admission.shares import DEFAULT_PREFIX_V4, DEFAULT_PREFIX_V6
from .foxglove import FoxgloveOptions
from .udp.transport import UdpOptions
from .websocket import WebSocketOptions

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping
    from pathlib import Path

    from rwt_graph.rosapi import VisibilityFor
    from rwt_graph.safety.rules import SafetyRules

    from .http.mcp_options import McpOptions
    from .webrtc.signalling import WebRtcOptions
    from .workers.placement import Placement

__all__ = ["MiB", "ServerConfig"]

MiB = 1024 * 1024


@dataclass(frozen=True)
class ServerConfig:
    """Settings of a server (names follow rosbridge's parameters where it has one).

    Attributes:
        host: address every listener binds (``--host``).
        port: WebSocket port (``--port``; 0 picks a free one; None: no WebSocket).
        tcp_port: TCP port (``--tcp-port``; None: no TCP listener).
        udp_port: UDP port (``--udp-port``; None: no UDP socket).
        stdio: serve one session over stdin/stdout (``--stdio``); the server
            stops when that session ends.
        stdio_fds: the (read, write) file descriptors of that session when not
            stdin/stdout (a pipe pair or a socket, for embedding and tests).
        max_message_size: largest incoming message on every transport, bytes.
        max_fragment_memory: bytes of incomplete ``fragment``/``png`` messages, and
            of TCP and WebSocket frames still arriving, all connections may hold
            together (``--max-fragment-memory``); a part past it is refused with an
            error status and its message dropped, a frame skipped (TCP) or its
            connection closed (WebSocket, 1013)
            (``rwt_protocol.framing.fragments.FragmentBudget``, docs/limits.md).
        memory_budget: bytes every connection together may make the server hold
            (``--memory-budget``, D44): outboxes (topic messages, replies, asset
            files), png messages waiting to be deflated, incomplete messages (within
            ``max_fragment_memory``) and WebRTC input not read yet. While it is full,
            clients that do not read lose their oldest topic messages and are closed
            as slow consumers, and what would grow it is refused
            (``rwt_protocol.runtime.memory.MemoryBudget``, docs/limits.md).
        max_connections: most simultaneous connections over all transports
            (``--max-connections``); a stream socket counts from ``accept()``,
            before its TLS/WebSocket handshake, and an MCP session holds
            ``http.mcp.SESSION_SLOTS`` plus one per request beyond them (D40).
            None: derived from the soft RLIMIT_NOFILE when serving starts
            (``process.fdlimit.default_max_connections``).
        max_connections_per_host: connections one host (``host_prefix_v4``,
            ``host_prefix_v6``) may hold once ``admission.shares.SHARES_FROM`` of
            ``max_connections`` are taken (``--max-connections-per-host``); before
            that anyone gets one, so local use, where every client is 127.0.0.1, is
            not limited. WebSocket, TCP, UDP, WebRTC and MCP count; stdio and
            in-process connections do not. A host's MCP sessions count against
            it from the first (D40).
        host_prefix_v4: leading bits of an IPv4 source address (or IPv4-mapped
            IPv6 one) that name its host for the per-host shares, 0 to 32
            (``--host-prefix-v4``; 24: a /24 is one host).
        host_prefix_v6: the same for IPv6, 0 to 128 (``--host-prefix-v6``; by
            default the /64 one machine gets).
        idle_timeout_s: seconds after which a WebSocket or TCP connection whose peer
            sent nothing and that holds nothing is closed (``--idle-timeout``;
            ``rwt_protocol.runtime.idle``), and an MCP session without a request in
            flight ends (D40); None: never. UDP has ``udp.idle_timeout_s``.
        certfile: PEM certificate (chain) for TLS on WebSocket and TCP (``--certfile``).
        keyfile: PEM private key for it (``--keyfile``).
        shutdown_grace_s: seconds a stopping server waits for connections to
            close before cutting them.
        session: per-connection protocol settings (limits, access, auth).
        websocket: WebSocket settings.
        foxglove: where Foxglove clients are answered (docs/foxglove.md): on the
            WebSocket port by default, and on ``foxglove.port`` if set. With an
            authenticator, a Foxglove client is admitted by the token in its URL
            (``AuthMode.URL_TOKEN``, checked by ``GraphServer.entry``; Foxglove has no
            ``auth`` op).
        udp: UDP settings.
        rosapi: offer the ``/rosapi/*`` services.
        rosapi_visibility: what each client may see through rosapi; by default
            what ``session.access`` allows.
        tf: offer tf2_web_republisher's action, actionlib topics and service with a
            TF buffer fed by ``/tf`` and ``/tf_static`` (``rwt serve --no-tf``: off).
        handshake_timeout_s: seconds an accepted WebSocket or TLS socket has to
            finish its handshake before it is closed (``--handshake-timeout``).
        clients_interval_s: ``/client_count`` and ``/connected_clients`` are
            published at most once per this many seconds, with the latest state
            (the first change at once), so connection churn costs O(changes).
        clients_fanout_per_s: most client-list entries (``/connected_clients``)
            sent per second over all its subscribers: a publish sends the whole
            list to each, clients x subscribers entries (about 60 bytes each), so
            with many of both the interval grows to that over this rate.
        reuse_port: bind WebSocket and TCP with SO_REUSEPORT, so the workers of
            ``rwt serve --workers N`` share one port (Linux spreads connections).
        listen_fds: listening sockets this process inherited, by listener kind
            (``websocket``, ``tcp``): descriptors it accepts from instead of
            binding that kind's port (a worker of ``rwt serve --workers N``,
            whose parent listens: workers.py); each is closed with the server.
        on_connections: called with the number of connections served after each
            one opens or closes (a worker's count for its parent,
            ``worker_counts``); None: not called.
        placement: move a rosbridge WebSocket connection to the worker that owns its
            first topic (``rwt serve --workers N --placement topic``, workers/placement.py,
            D57); None: every connection stays where the kernel put it.
        webrtc: answer WebRTC offers on the WebSocket port (``--webrtc``,
            docs/webrtc.md; needs ``rwt-rosbridge[webrtc]``); None: no WebRTC.
        mcp: serve MCP (Streamable HTTP) at ``/mcp`` on the WebSocket port
            (``--mcp``, docs/mcp.md; needs ``rwt-rosbridge[mcp]``); None: no MCP.
        use_sim_time: while serving, the latest ``/clock`` (rosgraph_msgs/msg/Clock)
            is the graph's timeline, which Foxglove clients get as server time
            (``--use-sim-time``; ``rwt_graph.simtime``, docs/foxglove.md).
        http_options: the options of an HTTP front end of the registry
            (``frontends_registry.HTTP_FRONTENDS``) by its name; None turns it
            off (``{"http": None}``: ``rwt serve --no-http-api``, docs/http.md);
            one not named runs with its default options (``webrtc`` and ``mcp``:
            the fields above).
        bearer_token: with an authenticator, checks the ``Authorization: Bearer``
            token of every HTTP front end's request (the video server's tokens,
            ``/rwt/video_token``; ``AuthMode.BEARER``); None: such requests are
            refused (401), unless ``webrtc``'s or ``mcp``'s own check is set.
        safety: the safety envelope's rules (``--safety FILE``, docs/safety.md):
            bounds, rates, dead-man stops and approvals for what remote clients
            command, put on the graph when the server is made (``Graph.use_safety``;
            a graph made with its own is kept); None: none.
    """

    host: str = "127.0.0.1"
    port: int | None = 9090
    tcp_port: int | None = None
    udp_port: int | None = None
    stdio: bool = False
    stdio_fds: tuple[int, int] | None = None
    max_message_size: int = 10 * MiB
    max_fragment_memory: int = 256 * MiB
    memory_budget: int = DEFAULT_MEMORY_BUDGET
    max_connections: int | None = None
    max_connections_per_host: int = 64
    host_prefix_v4: int = DEFAULT_PREFIX_V4
    host_prefix_v6: int = DEFAULT_PREFIX_V6
    idle_timeout_s: float | None = 600.0
    certfile: Path | None = None
    keyfile: Path | None = None
    shutdown_grace_s: float = 5.0
    session: SessionConfig = field(default_factory=SessionConfig)
    websocket: WebSocketOptions = field(default_factory=WebSocketOptions)
    foxglove: FoxgloveOptions = field(default_factory=FoxgloveOptions)
    udp: UdpOptions = field(default_factory=UdpOptions)
    rosapi: bool = True
    rosapi_visibility: VisibilityFor | None = None
    tf: bool = True
    handshake_timeout_s: float = 10.0
    clients_interval_s: float = 0.5
    clients_fanout_per_s: float = 200_000.0
    reuse_port: bool = False
    listen_fds: Mapping[str, tuple[int, ...]] = field(default_factory=dict)
    on_connections: Callable[[int], None] | None = None
    placement: Placement | None = None
    use_sim_time: bool = False
    webrtc: WebRtcOptions | None = None
    mcp: McpOptions | None = None
    http_options: Mapping[str, object] = field(default_factory=dict)
    bearer_token: Callable[[str], bool] | None = None
    safety: SafetyRules | None = None
