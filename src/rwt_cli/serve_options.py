"""The options of ``rwt serve``, in the groups its ``--help`` shows them in.

Each group is a dataclass of typer options (``rwt_cli.groups``); ``ServeOptions``
holds one of each. The option names are the fields' names (``tcp_port`` is
``--tcp-port``) and are the CLI's interface: renaming a field renames an option.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Annotated, ClassVar

import typer

from rwt_bag.formats import BagFormat, ChunkCompression
from rwt_protocol.distribution import install_hint
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.memory import DEFAULT_MEMORY_BUDGET
from rwt_protocol.runtime.rules import HOLD_BUDGET_S
from rwt_protocol.server.compat import Compat
from rwt_transports.admission.shares import DEFAULT_PREFIX_V4, DEFAULT_PREFIX_V6
from rwt_transports.process.allocator import HEAP_KEEP_MIB, HEAP_TRIM_S
from rwt_zenoh.limits import MAX_OUTBOX_BYTES, MAX_QUEUED_BYTES, MAX_REMOTE_ENTITIES

from .bag_options import (
    Check,
    ChunkCompressionLevel,
    ChunkCompressionOption,
    Clock,
    Delay,
    DialectOption,
    ExcludeRegex,
    ExcludeTopics,
    Format,
    Loop,
    MaxBagDuration,
    MaxBagSize,
    PlaybackDuration,
    PlaybackUntil,
    Prefix,
    Rate,
    RecordMaxSize,
    RecordSplit,
    RegexOption,
    Remap,
    RepeatLatched,
    SplitDuration,
    SplitSize,
    StartOffset,
    StartPaused,
    WaitForSubscribers,
    WaitTimeout,
)
from .checks import (
    check_directories,
    check_glob_list,
    check_ice_servers,
    check_readable_file,
    check_webrtc_stack,
)
from .options import MIB, PORT_RANGE, UVLOOP_EXTRA, VIDEO_PORT, LevelName, LogLevel
from .zenoh_link import ZENOH_EXTRA

__all__ = [
    "GraphOptions",
    "Limits",
    "Listeners",
    "Media",
    "PlayOptions",
    "Process",
    "RecordOptions",
    "Ros2",
    "ScaleOut",
    "Security",
    "ServeOptions",
    "ZenohMode",
    "ZenohRmwCompat",
]


class ZenohMode(StrEnum):
    """How ``rwt serve --zenoh`` joins: as a peer, or as a client of a router."""

    PEER = "peer"
    CLIENT = "client"


class PlacementMode(StrEnum):
    """``rwt serve --workers N --placement``: where a connection is served (D57)."""

    NONE = "none"
    TOPIC = "topic"


class ZenohRmwCompat(StrEnum):
    """Which rmw_zenoh's token defaults ``rwt serve --zenoh`` speaks (docs/zenoh.md)."""

    CURRENT = "current"
    PRE_2025 = "pre-2025"


@dataclass(frozen=True)
class Listeners:
    """Where and how the server listens: WebSocket, TCP, UDP, stdio."""

    PANEL: ClassVar[str] = "Listeners"

    host: Annotated[str, typer.Option(help="Address every listener binds.")] = "127.0.0.1"
    port: Annotated[
        int, typer.Option(**PORT_RANGE, help="WebSocket port; 0 picks a free port.")
    ] = 9090
    websocket: Annotated[
        bool, typer.Option(help="Serve WebSocket on --port (--no-websocket: don't).")
    ] = True
    tcp_port: Annotated[
        int | None,
        typer.Option(**PORT_RANGE, help="Also serve raw TCP on this port (0: a free one)."),
    ] = None
    udp_port: Annotated[
        int | None,
        typer.Option(**PORT_RANGE, help="Also serve UDP on this port (0: a free one)."),
    ] = None
    stdio: Annotated[
        bool, typer.Option(help="Also serve one session on stdin/stdout; stop when it ends.")
    ] = False
    url_path: Annotated[
        str | None, typer.Option(help="Only accept WebSocket connections on this path.")
    ] = None
    websocket_compression: Annotated[bool, typer.Option(help="Offer permessage-deflate.")] = False
    webrtc: Annotated[
        bool,
        typer.Option(
            help="Answer WebRTC offers at POST /webrtc on --port; a 'rosbridge' data channel"
            " is a session, ?video=TOPIC sends an image topic as a video track"
            " (docs/webrtc.md; needs rwt-rosbridge[webrtc])."
        ),
    ] = False
    webrtc_stack: Annotated[
        str,
        typer.Option(
            metavar="STACK",
            callback=check_webrtc_stack,
            help="The WebRTC stack of --webrtc's data channels: reactor (libwebrtc's SCTP),"
            " native (libdatachannel, Python 3.12+; also video tracks), aiortc, or auto"
            " (the best installed); offers with audio or video and no ?video= stay on"
            " aiortc (docs/webrtc.md, 'Which stack').",
        ),
    ] = "auto"
    ice_server: Annotated[
        list[str] | None,
        typer.Option(
            metavar="URL",
            callback=check_ice_servers,
            help="A STUN or TURN server for --webrtc's candidates behind NAT: stun:HOST[:PORT],"
            " turn:USER:PASS@HOST[:PORT][?transport=tcp], turns:USER:PASS@HOST[:PORT];"
            " repeatable, one of each (docs/webrtc.md, 'Through NAT').",
        ),
    ] = None
    http_api: Annotated[
        bool,
        typer.Option(
            help="Answer the HTTP API on --port: /api/topics, /api/services, /api/actions"
            " (JSON, Server-Sent Events) and /openapi.json (docs/http.md; --no-http-api: off)."
        ),
    ] = True
    mcp: Annotated[
        bool,
        typer.Option(
            help="Serve MCP (Streamable HTTP) for AI agents at /mcp on --port: the tools of"
            " 'rwt mcp' on this graph (docs/mcp.md; needs rwt-rosbridge[mcp])."
        ),
    ] = False
    mcp_read_only: Annotated[
        bool,
        typer.Option(
            help="With --mcp: refuse the tools that change the robot (publish, calls, goals,"
            " cancel, set_parameter)."
        ),
    ] = False
    mcp_authorization_server: Annotated[
        str | None,
        typer.Option(
            help="With --mcp: the OAuth 2.1 authorization server (its issuer URL, https://...)"
            " that /.well-known/oauth-protected-resource names for /mcp (RFC 9728;"
            " docs/mcp.md, 'Authorization')."
        ),
    ] = None
    websocket_ping_interval: Annotated[
        float, typer.Option(help="Seconds between WebSocket keepalive pings (0: none).")
    ] = 0.0
    websocket_ping_timeout: Annotated[
        float, typer.Option(help="Seconds to wait for a pong before closing.")
    ] = 30.0
    udp_datagram_size: Annotated[
        int, typer.Option(help="Outgoing UDP messages above this many bytes are fragmented.")
    ] = 8192
    foxglove: Annotated[
        bool,
        typer.Option(
            help="Answer Foxglove clients (subprotocol foxglove.sdk.v1 or foxglove.websocket.v1) "
            "on --port (--no-foxglove: rosbridge only)."
        ),
    ] = True
    foxglove_port: Annotated[
        int | None,
        typer.Option(
            **PORT_RANGE, help="Also serve a Foxglove-only WebSocket on this port (0: a free one)."
        ),
    ] = None
    package_path: Annotated[
        list[Path] | None,
        typer.Option(
            callback=check_directories,
            metavar="DIR",
            help="Serve package:// assets (meshes, textures, URDF) to Foxglove clients from the "
            "packages in DIR, as ROS_PACKAGE_PATH does; repeatable.",
        ),
    ] = None
    assets: Annotated[
        bool,
        typer.Option(
            help="Answer Foxglove's fetchAsset from --package-path, ROS_PACKAGE_PATH and the "
            "share folders of AMENT_PREFIX_PATH (--no-assets: never)."
        ),
    ] = True
    foxglove_show_plumbing: Annotated[
        bool,
        typer.Option(
            help="Show Foxglove clients rwt's own helpers too: rosapi's services, /client_count, "
            "/connected_clients, the TF republisher and their nodes (/rosapi, "
            "/rosbridge_websocket, /tf2_web_republisher) in the connection graph. By default "
            "they see the robot's topics, services and nodes, a rosbridge client's own "
            "(/rwt_client_<n>) included."
        ),
    ] = False


@dataclass(frozen=True)
class Security:
    """TLS, rosauth, and what clients may reach."""

    PANEL: ClassVar[str] = "Security"

    certfile: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file,
            metavar="FILE",
            help="PEM certificate: TLS (wss, TLS over TCP).",
        ),
    ] = None
    keyfile: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file, metavar="FILE", help="PEM private key for --certfile."
        ),
    ] = None
    auth_secret_file: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file,
            metavar="FILE",
            help="rosauth secret (its first line): clients must send auth first.",
        ),
    ] = None
    auth_bind_connection: Annotated[
        bool,
        typer.Option(
            help="With --auth-secret-file: send each connection a challenge first and "
            "accept only an auth whose rand is it, signed with rwt's bound MAC "
            "(no replay on another connection; not rosauth-compatible).",
        ),
    ] = False
    topics_glob: Annotated[
        str,
        typer.Option(
            callback=check_glob_list,
            metavar="PATTERNS",
            help="Allowed topics: fnmatch patterns, as /a/*,/b or [/a/*, /b] (default: all).",
        ),
    ] = ""
    topics_pub_glob: Annotated[
        str,
        typer.Option(
            callback=check_glob_list,
            metavar="PATTERNS",
            help="Topics clients may advertise and publish, merged with --topics-glob;"
            " [] with no --topics-glob allows none (default: --topics-glob's).",
        ),
    ] = ""
    topics_sub_glob: Annotated[
        str,
        typer.Option(
            callback=check_glob_list,
            metavar="PATTERNS",
            help="Topics clients may subscribe to, merged with --topics-glob;"
            " [] with no --topics-glob allows none (default: --topics-glob's).",
        ),
    ] = ""
    services_glob: Annotated[
        str,
        typer.Option(
            callback=check_glob_list,
            metavar="PATTERNS",
            help="Allowed services (/rosapi/* always allowed).",
        ),
    ] = ""
    params_glob: Annotated[
        str, typer.Option(callback=check_glob_list, metavar="PATTERNS", help="Allowed parameters.")
    ] = ""
    actions_glob: Annotated[
        str, typer.Option(callback=check_glob_list, metavar="PATTERNS", help="Allowed actions.")
    ] = ""
    allowed_origins: Annotated[
        str,
        typer.Option(
            metavar="PATTERNS",
            help="Accepted WebSocket Origin patterns, comma-separated (default: any).",
        ),
    ] = ""
    udp_trust_source_address: Annotated[
        bool,
        typer.Option(
            help="Serve UDP peers without validating their address (only on a trusted link)."
        ),
    ] = False
    safety: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file,
            metavar="FILE",
            help="Safety rules (TOML) for what remote clients command: field bounds "
            "(clamp or reject), rates, dead-man stops, a person's approval for MCP agents.",
        ),
    ] = None


@dataclass(frozen=True)
class Limits:
    """Caps on messages, connections, queues and time (docs/limits.md)."""

    PANEL: ClassVar[str] = "Limits"

    max_message_size: Annotated[
        int,
        typer.Option(
            min=1,
            help="Largest incoming message on every transport, also reassembled from parts, bytes.",
        ),
    ] = 10 * MIB
    max_pending_fragments: Annotated[
        int, typer.Option(min=1, help="Messages per connection whose fragments are arriving.")
    ] = 16
    max_fragment_memory: Annotated[
        int,
        typer.Option(
            min=1,
            help="Bytes of incomplete messages (fragments, frames still arriving)"
            " all connections hold together.",
        ),
    ] = 256 * MIB
    memory_budget: Annotated[
        int,
        typer.Option(
            min=1,
            help="Bytes all connections may make the server hold together: outboxes,"
            " asset files, png messages waiting, incomplete messages, WebRTC input"
            " (docs/limits.md).",
        ),
    ] = DEFAULT_MEMORY_BUDGET
    fragment_timeout: Annotated[
        float, typer.Option(min=0.001, help="Seconds without a new fragment before dropping.")
    ] = 600.0
    max_queue_length: Annotated[
        int, typer.Option(min=1, help="Cap on a throttled subscription's queue_length.")
    ] = 100
    qos_lifespan: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="Seconds after its publication a message is no longer sent to a subscriber"
            " whose qos gives no lifespan (protocol 2.1.0; 0: none, as rosbridge_suite).",
        ),
    ] = 0.0
    max_subscriptions: Annotated[
        int, typer.Option(min=1, help="Topics one connection may subscribe to at once.")
    ] = 1000
    max_advertisements: Annotated[
        int, typer.Option(min=1, help="Topics, services and actions one connection advertises.")
    ] = 1000
    max_pending_calls: Annotated[
        int, typer.Option(min=1, help="Service calls of one connection awaiting their reply.")
    ] = 1000
    max_pending_goals: Annotated[
        int, typer.Option(min=1, help="Action goals of one connection awaiting their result.")
    ] = 1000
    png_inflate_rate: Annotated[
        int,
        typer.Option(
            min=1,
            help="Bytes a second of png images one connection may have inflated (after a"
            " burst of --max-message-size); its later png ops wait.",
        ),
    ] = 8 * MIB
    send_buffer_limit: Annotated[
        int,
        typer.Option(
            min=1,
            help="Outgoing bytes queued per connection (payload plus a fixed cost a frame)"
            " before dropping topic messages.",
        ),
    ] = 16 * MIB
    send_timeout: Annotated[
        float, typer.Option(help="Seconds a connection may stay over the send buffer limit.")
    ] = 30.0
    hold_budget: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="Seconds a publisher may be held back by subscribers reading slower than"
            " it publishes (in all, regaining a tenth of a second a second); then they"
            " lose their oldest messages instead.",
        ),
    ] = HOLD_BUDGET_S
    max_connections: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Most simultaneous connections (all transports; a socket counts from accept)."
            " Default: the soft RLIMIT_NOFILE minus a reserve of min(128, limit/2) + 16.",
        ),
    ] = None
    max_connections_per_host: Annotated[
        int,
        typer.Option(
            min=1,
            help="Connections one host (see --host-prefix-v4/-v6) may hold once 3/4 of"
            " --max-connections are taken; MCP sessions (--mcp) from the first.",
        ),
    ] = 64
    host_prefix_v4: Annotated[
        int,
        typer.Option(
            min=0,
            max=ipaddress.IPV4LENGTH,
            metavar="BITS",
            help="IPv4 clients (and IPv4-mapped IPv6 ones) whose addresses share this"
            " many leading bits count as one host for the per-host shares (24: a /24).",
        ),
    ] = DEFAULT_PREFIX_V4
    host_prefix_v6: Annotated[
        int,
        typer.Option(
            min=0,
            max=ipaddress.IPV6LENGTH,
            metavar="BITS",
            help="IPv6 clients whose addresses share this many leading bits count as one"
            " host for the per-host shares (64: the /64 one machine gets).",
        ),
    ] = DEFAULT_PREFIX_V6
    idle_timeout: Annotated[
        float,
        typer.Option(
            min=0,
            help="Seconds after which a WebSocket or TCP connection that sent nothing and"
            " holds nothing (no subscription, advertisement, call...) is closed, and an MCP"
            " session without a request ends; 0: never.",
        ),
    ] = 600.0
    call_timeout: Annotated[
        float, typer.Option(help="Seconds a call_service without timeout may wait; 0 = no limit.")
    ] = 30.0
    handshake_timeout: Annotated[
        float,
        typer.Option(
            min=0.001, help="Seconds an accepted socket has to finish its TLS/WebSocket handshake."
        ),
    ] = 10.0
    udp_max_sessions: Annotated[
        int, typer.Option(min=1, help="Most UDP sessions at once (within --max-connections).")
    ] = 256
    udp_max_sessions_per_host: Annotated[
        int,
        typer.Option(
            min=1, help="UDP sessions one host may hold once 3/4 of --udp-max-sessions are taken."
        ),
    ] = 16
    udp_idle_timeout: Annotated[
        float, typer.Option(help="Seconds of silence after which a UDP peer is forgotten.")
    ] = 300.0


@dataclass(frozen=True)
class GraphOptions:
    """The graph's message types and what it offers besides the clients' own."""

    PANEL: ClassVar[str] = "Graph"

    dialect: DialectOption = None
    interfaces: Annotated[
        list[Path] | None,
        typer.Option(
            callback=check_directories,
            metavar="DIR",
            help="Extra interface directory, laid out as PKG/msg, PKG/srv, PKG/action; repeatable.",
        ),
    ] = None
    status_level: Annotated[LevelName, typer.Option(help="Status level of new connections.")] = (
        LevelName[StatusLevel.ERROR.name]
    )
    compat: Annotated[
        Compat,
        typer.Option(
            help="rosbridge: behave as rosbridge_suite where clients notice (no status op"
            " until a client sends set_level, its reply texts); rosbridge-2.1: also, as 2.1.0,"
            " a publish with type does not advertise, so one to an unknown topic is refused"
            " (docs/differences.md)."
        ),
    ] = Compat.RWT
    tf: Annotated[
        bool,
        typer.Option(help="Offer tf2_web_republisher (/tf2_web_republisher, /republish_tfs)."),
    ] = True
    use_sim_time: Annotated[
        bool,
        typer.Option(
            help="Give Foxglove clients the latest /clock (rosgraph_msgs/msg/Clock) as server "
            "time, as use_sim_time does."
        ),
    ] = False


@dataclass(frozen=True)
class Media:
    """The web console, images over HTTP and depth clouds."""

    PANEL: ClassVar[str] = "Console and media"

    console: Annotated[
        bool | None,
        typer.Option(
            help="Serve the web console at http://HOST:PORT/ (default: on, off with"
            " --allowed-origins)."
        ),
    ] = None
    video: Annotated[
        bool, typer.Option(help="Also serve image topics over HTTP (as web_video_server).")
    ] = False
    video_port: Annotated[
        int | None,
        typer.Option(
            **PORT_RANGE,
            help=f"HTTP port of the video server (default {VIDEO_PORT}; 0 picks a free one);"
            " implies --video.",
        ),
    ] = None
    video_max_connections: Annotated[
        int, typer.Option(min=1, help="Most HTTP connections of --video at once (503 beyond).")
    ] = 64
    video_max_streams: Annotated[
        int, typer.Option(min=1, help="Most distinct --video streams (encoders) at once.")
    ] = 16
    depthcloud: Annotated[
        str | None,
        typer.Option(
            metavar="DEPTH_TOPIC[,RGB_TOPIC]",
            help="Encode this depth (and colour) topic on /depthcloud_encoded (ros3djs).",
        ),
    ] = None
    depthcloud_max_depth: Annotated[
        float, typer.Option(min=0.001, help="Metres per depth tile (near 0..d, far d..2d).")
    ] = 1.0
    depthcloud_tile_size: Annotated[
        int, typer.Option(min=16, help="Side of each depth-cloud tile, pixels.")
    ] = 512


RECORD_AND_REPLAY = "Record and replay"


@dataclass(frozen=True)
class RecordOptions:
    """``--record BAG``: the graph's topics into a bag while serving."""

    PANEL: ClassVar[str] = RECORD_AND_REPLAY

    record: Annotated[
        Path | None, typer.Option(metavar="BAG", help="Record the graph's topics into this bag.")
    ] = None
    record_topics: Annotated[
        str,
        typer.Option(callback=check_glob_list, metavar="PATTERNS", help="Topics --record records."),
    ] = ""
    record_regex: RegexOption = None
    record_exclude_regex: ExcludeRegex = None
    record_exclude_topics: ExcludeTopics = None
    record_format: Format = BagFormat.MCAP
    record_max_bag_size: MaxBagSize = None
    record_max_bag_duration: MaxBagDuration = None
    record_split_size: SplitSize = None
    record_split_duration: SplitDuration = None
    record_chunk_compression: ChunkCompressionOption = ChunkCompression.NONE
    record_chunk_compression_level: ChunkCompressionLevel = None
    record_repeat_latched: RepeatLatched = True
    record_max_size: RecordMaxSize = None
    record_split: RecordSplit = False


@dataclass(frozen=True)
class PlayOptions:
    """``--play BAG``: a bag's topics into the graph with their timing."""

    PANEL: ClassVar[str] = RECORD_AND_REPLAY

    play: Annotated[
        list[Path] | None,
        typer.Option(metavar="BAG", help="Play this bag into the graph (repeat: split parts)."),
    ] = None
    play_topics: Annotated[
        str, typer.Option(callback=check_glob_list, metavar="PATTERNS", help="Topics --play plays.")
    ] = ""
    rate: Rate = 1.0
    loop: Loop = False
    start_offset: StartOffset = 0.0
    clock: Clock = None
    play_check: Check = True
    start_paused: StartPaused = False
    remap: Remap = None
    delay: Delay = 0.0
    playback_duration: PlaybackDuration = None
    playback_until_sec: PlaybackUntil = None
    play_prefix: Prefix = ""
    wait_for_subscribers: WaitForSubscribers = False
    wait_for_subscribers_timeout: WaitTimeout = None


@dataclass(frozen=True)
class ScaleOut:
    """One graph shared by several servers (and ROS 2 nodes) over Zenoh."""

    PANEL: ClassVar[str] = "Scale-out (Zenoh)"

    zenoh: Annotated[
        bool, typer.Option(help=f"Share the graph over a Zenoh network ({ZENOH_EXTRA}).")
    ] = False
    zenoh_config: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file, metavar="FILE", help="Zenoh's JSON5 config file."
        ),
    ] = None
    zenoh_connect: Annotated[
        list[str] | None,
        typer.Option(metavar="ENDPOINT", help="Zenoh endpoint to connect to; repeatable."),
    ] = None
    zenoh_listen: Annotated[
        list[str] | None,
        typer.Option(
            metavar="ENDPOINT",
            help="Zenoh endpoint to listen on (tcp/127.0.0.1:0 if none); repeatable.",
        ),
    ] = None
    zenoh_mode: Annotated[
        ZenohMode, typer.Option(help="Join as a Zenoh peer, or as a client of a router.")
    ] = ZenohMode.PEER
    zenoh_rmw_compat: Annotated[
        ZenohRmwCompat,
        typer.Option(
            help="rmw_zenoh's token defaults: 'current' (March 2025 on: empty durability is "
            "volatile) or 'pre-2025' (it is transient local)."
        ),
    ] = ZenohRmwCompat.CURRENT
    zenoh_queue_bytes: Annotated[
        int,
        typer.Option(
            min=64 * 1024,
            metavar="BYTES",
            help="Bytes of Zenoh samples waiting to be handled; past it the oldest of the "
            "busiest topic are dropped. Also the largest Zenoh message accepted.",
        ),
    ] = MAX_QUEUED_BYTES
    zenoh_outbox_bytes: Annotated[
        int,
        typer.Option(
            min=64 * 1024,
            metavar="BYTES",
            help="Bytes of local messages waiting to go out on Zenoh; past half of it the "
            "publishing connection is held back, past all of it the oldest are dropped.",
        ),
    ] = MAX_OUTBOX_BYTES
    zenoh_max_entities: Annotated[
        int,
        typer.Option(
            min=1, help="Remote Zenoh entities (liveliness tokens) mirrored; more are ignored."
        ),
    ] = MAX_REMOTE_ENTITIES
    domain_id: Annotated[
        int | None,
        typer.Option(min=0, help="ROS domain on Zenoh (default: ROS_DOMAIN_ID, else 0)."),
    ] = None
    workers: Annotated[
        int,
        typer.Option(
            min=1,
            help="Server processes accepting from the same listening ports (Linux) and "
            "sharing one graph over Zenoh on loopback; restarted when they die.",
        ),
    ] = 1
    placement: Annotated[
        PlacementMode,
        typer.Option(
            help="With --workers: 'topic' moves a rosbridge WebSocket connection to the worker "
            "that owns the topic of its first subscribe, advertise or publish, so a topic's "
            "messages stay in one worker; 'none' serves each where the kernel put it.",
        ),
    ] = PlacementMode.NONE
    reuse_port: Annotated[bool, typer.Option(hidden=True)] = False
    listen_fd: Annotated[list[str] | None, typer.Option(hidden=True)] = None
    worker_state: Annotated[str | None, typer.Option(hidden=True)] = None
    worker_count: Annotated[int, typer.Option(hidden=True, min=1)] = 1


@dataclass(frozen=True)
class Ros2:
    """The link to a ROS 2 graph through rclpy (docs/ros2.md)."""

    PANEL: ClassVar[str] = "ROS 2"

    ros2: Annotated[
        bool,
        typer.Option(
            help=f"Link the graph to ROS 2 through rclpy (ROS sourced, or {install_hint('ros2')});"
            " ROS_DOMAIN_ID and the middleware come from the environment."
        ),
    ] = False
    ros2_node_name: Annotated[
        str, typer.Option(help="Name of the rclpy node standing for the graph.")
    ] = "rwt"
    ros2_namespace: Annotated[str, typer.Option(help="Namespace of that node.")] = "/"


@dataclass(frozen=True)
class Process:
    """The server process: logging, event loop, memory, file descriptors."""

    PANEL: ClassVar[str] = "Process"

    log_level: Annotated[LogLevel, typer.Option(help="Log level on stderr.")] = LogLevel.INFO
    uvloop: Annotated[
        bool, typer.Option(help=f"Run on uvloop (install it with: {UVLOOP_EXTRA}).")
    ] = False
    heap_keep: Annotated[
        int,
        typer.Option(
            min=0,
            help="MiB of freed heap kept for the next large message (glibc); 0: the "
            "system default, which maps and unmaps every buffer of a large message.",
        ),
    ] = HEAP_KEEP_MIB
    heap_trim: Annotated[
        float,
        typer.Option(
            min=0,
            help="Seconds between two returns of all freed heap to the system (glibc's "
            "malloc_trim; --heap-keep's too, once a period); 0: never.",
        ),
    ] = HEAP_TRIM_S
    raise_fd_limit: Annotated[
        bool, typer.Option(help="Raise the soft RLIMIT_NOFILE to the hard limit at start-up.")
    ] = True


@dataclass(frozen=True)
class ServeOptions:
    """Every option of ``rwt serve``, a field a help section, in the order shown."""

    listeners: Listeners
    security: Security
    limits: Limits
    graph: GraphOptions
    media: Media
    record: RecordOptions
    play: PlayOptions
    scale_out: ScaleOut
    ros2: Ros2
    process: Process
