"""The ``rwt`` command line: ``rwt serve`` and ``rwt conformance``.

``rwt serve`` runs every transport asked for on one graph (D22). Its help text,
the docstring of ``serve``, is what users read: it names no internal documents.
Bad option values are refused at start with a one-line usage error (exit code 2,
see ``cli_checks``); an address that cannot be bound names its listener (exit 1).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import logging
import signal
import sys
from collections.abc import Sequence
from dataclasses import replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, NoReturn
from urllib.parse import urlsplit

import anyio
import typer
from anyio.abc import TaskStatus
from typer.core import TyperGroup

from rwt_bag.errors import BagError
from rwt_bag.formats import BagFormat, ChunkCompression
from rwt_conformance.cli import conformance
from rwt_console import ConsoleSite
from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.access import AccessPolicy, parse_glob_list
from rwt_protocol.levels import StatusLevel
from rwt_protocol.session import HOLD_BUDGET_S, SessionConfig
from rwt_zenoh.limits import MAX_QUEUED_BYTES, MAX_REMOTE_ENTITIES

from .allocator import HEAP_KEEP_MIB, tune_allocator
from .cli_bag import (
    Check,
    ChunkCompressionLevel,
    ChunkCompressionOption,
    Clock,
    Delay,
    DialectOption,
    DisableKeyboardControls,
    ExcludeRegex,
    ExcludeTopics,
    Format,
    Interfaces,
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
    bag_app,
    bag_jobs,
    chunk_compression,
    dialect_for,
    play_options,
    record,
    record_options,
    split_policy,
    terminal_keys,
    topic_selection,
)
from .cli_checks import (
    ClickException,
    ListenError,
    NoArgsIsHelpError,
    OptionError,
    check_directories,
    check_glob_list,
    check_readable_file,
    check_tls,
    error_line,
    usage_error,
)
from .cli_ros2 import linked_ros2, ros2_interface_dirs, ros2_options
from .cli_zenoh import ZENOH_EXTRA, linked, require_zenoh, run_router, zenoh_options
from .fdlimit import raise_nofile_limit
from .gcfreeze import freeze_startup_objects
from .server import RosbridgeServer, ServerConfig, rosauth_authenticator
from .udp import UdpOptions
from .websocket import WebSocketOptions
from .workers import run_workers

if TYPE_CHECKING:
    from rwt_bag.jobs import BagJobs
    from rwt_ros2 import Ros2Options
    from rwt_video import VideoConfig
    from rwt_zenoh.config import ZenohOptions

__all__ = ["app", "main"]

MiB = 1024 * 1024
PORT_RANGE: dict[str, Any] = {"min": 0, "max": 65535}
VIDEO_PORT = 8080
UVLOOP_EXTRA = 'pip install "rwt[uvloop]"'


class _RwtGroup(TyperGroup):
    """The ``rwt`` group: an error is one line on stderr, not a usage box or a traceback."""

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        windows_expand_args: bool = True,
        **extra: Any,
    ) -> Any:
        """Run the command line; in standalone mode, exit with its code (2: a usage error)."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, False, windows_expand_args, **extra)
        try:
            code = super().main(
                args, prog_name or "rwt", complete_var, False, windows_expand_args, **extra
            )
        except ClickException as exc:
            if NoArgsIsHelpError is not None and isinstance(exc, NoArgsIsHelpError):
                typer.echo(str(exc), err=True)  # `rwt` alone: the help
            else:
                typer.echo(error_line(exc), err=True)
            sys.exit(getattr(exc, "exit_code", 1))
        except typer.Abort:
            typer.echo("rwt: aborted", err=True)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


# rich_markup_mode=None: click's plain help, which wraps at 80 columns where rich's
# tables cut option names, and prints [brackets] (rwt[uvloop]) instead of eating them
app = typer.Typer(
    cls=_RwtGroup,
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,
)


# typer offers an enum's values as choices: the status levels' wire spellings, made
# from StatusLevel itself so the two cannot differ (Dialect is a StrEnum already)
LevelName = StrEnum("LevelName", [(level.name, level.wire) for level in StatusLevel])  # type: ignore[misc]


class ZenohMode(StrEnum):
    """How ``rwt serve --zenoh`` joins: as a peer, or as a client of a router."""

    PEER = "peer"
    CLIENT = "client"


class ZenohRmwCompat(StrEnum):
    """Which rmw_zenoh's token defaults ``rwt serve --zenoh`` speaks (docs/zenoh.md)."""

    CURRENT = "current"
    PRE_2025 = "pre-2025"


class LogLevel(StrEnum):
    """Log levels as the CLI accepts them."""

    DEBUG = "debug"
    INFO = "info"
    WARNING = "warning"
    ERROR = "error"


def _print_version(value: bool) -> None:
    if value:
        try:
            version = importlib.metadata.version("rwt")
        except importlib.metadata.PackageNotFoundError:  # a source tree, not installed
            version = "0+unknown"  # as rwt.__version__
        typer.echo(f"rwt {version}")
        raise typer.Exit


@app.callback()
def main(
    version: Annotated[
        bool,
        typer.Option(
            "--version", is_eager=True, callback=_print_version, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """rwt: a ROS-free rosbridge v2 server, client and conformance suite.

    Run a server with 'rwt serve'; check one with 'rwt conformance URL'.
    """


app.command(short_help="Check a rosbridge server against the conformance suite.")(conformance)
app.command(short_help="Record topics of a rosbridge server into a bag.")(record)
app.add_typer(bag_app, name="bag", short_help="Inspect bags.")


@app.command(short_help="Run a rosbridge server.")
def serve(
    host: Annotated[str, typer.Option(help="Address every listener binds.")] = "127.0.0.1",
    port: Annotated[
        int, typer.Option(**PORT_RANGE, help="WebSocket port; 0 picks a free port.")
    ] = 9090,
    websocket: Annotated[
        bool, typer.Option(help="Serve WebSocket on --port (--no-websocket: don't).")
    ] = True,
    tcp_port: Annotated[
        int | None,
        typer.Option(**PORT_RANGE, help="Also serve raw TCP on this port (0: a free one)."),
    ] = None,
    udp_port: Annotated[
        int | None,
        typer.Option(**PORT_RANGE, help="Also serve UDP on this port (0: a free one)."),
    ] = None,
    stdio: Annotated[
        bool, typer.Option(help="Also serve one session on stdin/stdout; stop when it ends.")
    ] = False,
    dialect: DialectOption = None,
    interfaces: Annotated[
        list[Path] | None,
        typer.Option(
            callback=check_directories,
            metavar="DIR",
            help="Extra interface directory, laid out as PKG/msg, PKG/srv, PKG/action; repeatable.",
        ),
    ] = None,
    status_level: Annotated[
        LevelName, typer.Option(help="Status level of new connections.")
    ] = LevelName[StatusLevel.ERROR.name],
    max_message_size: Annotated[
        int,
        typer.Option(
            min=1,
            help="Largest incoming message on every transport, also reassembled from parts, bytes.",
        ),
    ] = 10 * MiB,
    max_pending_fragments: Annotated[
        int, typer.Option(min=1, help="Messages per connection whose fragments are arriving.")
    ] = 16,
    max_fragment_memory: Annotated[
        int,
        typer.Option(
            min=1, help="Bytes of incomplete fragmented messages all connections hold together."
        ),
    ] = 256 * MiB,
    fragment_timeout: Annotated[
        float, typer.Option(min=0.001, help="Seconds without a new fragment before dropping.")
    ] = 600.0,
    max_queue_length: Annotated[
        int, typer.Option(min=1, help="Cap on a throttled subscription's queue_length.")
    ] = 100,
    max_subscriptions: Annotated[
        int, typer.Option(min=1, help="Topics one connection may subscribe to at once.")
    ] = 1000,
    max_advertisements: Annotated[
        int, typer.Option(min=1, help="Topics, services and actions one connection advertises.")
    ] = 1000,
    max_pending_calls: Annotated[
        int, typer.Option(min=1, help="Service calls of one connection awaiting their reply.")
    ] = 1000,
    max_pending_goals: Annotated[
        int, typer.Option(min=1, help="Action goals of one connection awaiting their result.")
    ] = 1000,
    png_inflate_rate: Annotated[
        int,
        typer.Option(
            min=1,
            help="Bytes a second of png images one connection may have inflated (after a"
            " burst of --max-message-size); its later png ops wait.",
        ),
    ] = 8 * MiB,
    send_buffer_limit: Annotated[
        int,
        typer.Option(
            min=1,
            help="Outgoing bytes queued per connection (payload plus a fixed cost a frame)"
            " before dropping topic messages.",
        ),
    ] = 16 * MiB,
    send_timeout: Annotated[
        float, typer.Option(help="Seconds a connection may stay over the send buffer limit.")
    ] = 30.0,
    hold_budget: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="Seconds a connection that reads slower than its topics come may hold"
            " their publishers back (in all, until it catches up); then it loses its"
            " oldest messages instead.",
        ),
    ] = HOLD_BUDGET_S,
    max_connections: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Most simultaneous connections (all transports; a socket counts from accept)."
            " Default: the soft RLIMIT_NOFILE minus a reserve of min(128, limit/2) + 16.",
        ),
    ] = None,
    max_connections_per_host: Annotated[
        int,
        typer.Option(
            min=1,
            help="Connections one host (source IP) may hold once 3/4 of --max-connections"
            " are taken.",
        ),
    ] = 64,
    idle_timeout: Annotated[
        float,
        typer.Option(
            min=0,
            help="Seconds after which a WebSocket or TCP connection that sent nothing and"
            " holds nothing (no subscription, advertisement, call...) is closed; 0: never.",
        ),
    ] = 600.0,
    certfile: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file,
            metavar="FILE",
            help="PEM certificate: TLS (wss, TLS over TCP).",
        ),
    ] = None,
    keyfile: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file, metavar="FILE", help="PEM private key for --certfile."
        ),
    ] = None,
    auth_secret_file: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file,
            metavar="FILE",
            help="rosauth secret (its first line): clients must send auth first.",
        ),
    ] = None,
    auth_bind_connection: Annotated[
        bool,
        typer.Option(
            help="With --auth-secret-file: send each connection a challenge first and "
            "accept only an auth whose rand is it, signed with rwt's bound MAC "
            "(no replay on another connection; not rosauth-compatible).",
        ),
    ] = False,
    topics_glob: Annotated[
        str,
        typer.Option(
            callback=check_glob_list,
            metavar="PATTERNS",
            help="Allowed topics: fnmatch patterns, as /a/*,/b or [/a/*, /b] (default: all).",
        ),
    ] = "",
    services_glob: Annotated[
        str,
        typer.Option(
            callback=check_glob_list,
            metavar="PATTERNS",
            help="Allowed services (/rosapi/* always allowed).",
        ),
    ] = "",
    params_glob: Annotated[
        str, typer.Option(callback=check_glob_list, metavar="PATTERNS", help="Allowed parameters.")
    ] = "",
    actions_glob: Annotated[
        str, typer.Option(callback=check_glob_list, metavar="PATTERNS", help="Allowed actions.")
    ] = "",
    allowed_origins: Annotated[
        str,
        typer.Option(
            metavar="PATTERNS",
            help="Accepted WebSocket Origin patterns, comma-separated (default: any).",
        ),
    ] = "",
    call_timeout: Annotated[
        float, typer.Option(help="Seconds a call_service without timeout may wait; 0 = no limit.")
    ] = 30.0,
    url_path: Annotated[
        str | None, typer.Option(help="Only accept WebSocket connections on this path.")
    ] = None,
    websocket_compression: Annotated[bool, typer.Option(help="Offer permessage-deflate.")] = False,
    websocket_ping_interval: Annotated[
        float, typer.Option(help="Seconds between WebSocket keepalive pings (0: none).")
    ] = 0.0,
    websocket_ping_timeout: Annotated[
        float, typer.Option(help="Seconds to wait for a pong before closing.")
    ] = 30.0,
    udp_datagram_size: Annotated[
        int, typer.Option(help="Outgoing UDP messages above this many bytes are fragmented.")
    ] = 8192,
    udp_max_sessions: Annotated[
        int, typer.Option(min=1, help="Most UDP sessions at once (within --max-connections).")
    ] = 256,
    udp_max_sessions_per_host: Annotated[
        int,
        typer.Option(
            min=1, help="UDP sessions one host may hold once 3/4 of --udp-max-sessions are taken."
        ),
    ] = 16,
    udp_trust_source_address: Annotated[
        bool,
        typer.Option(
            help="Serve UDP peers without validating their address (only on a trusted link)."
        ),
    ] = False,
    udp_idle_timeout: Annotated[
        float, typer.Option(help="Seconds of silence after which a UDP peer is forgotten.")
    ] = 300.0,
    tf: Annotated[
        bool,
        typer.Option(help="Offer tf2_web_republisher (/tf2_web_republisher, /republish_tfs)."),
    ] = True,
    console: Annotated[
        bool | None,
        typer.Option(
            help="Serve the web console at http://HOST:PORT/ (default: on, off with"
            " --allowed-origins)."
        ),
    ] = None,
    video: Annotated[
        bool, typer.Option(help="Also serve image topics over HTTP (as web_video_server).")
    ] = False,
    video_port: Annotated[
        int | None,
        typer.Option(
            **PORT_RANGE,
            help=f"HTTP port of the video server (default {VIDEO_PORT}; 0 picks a free one);"
            " implies --video.",
        ),
    ] = None,
    video_max_connections: Annotated[
        int, typer.Option(min=1, help="Most HTTP connections of --video at once (503 beyond).")
    ] = 64,
    video_max_streams: Annotated[
        int, typer.Option(min=1, help="Most distinct --video streams (encoders) at once.")
    ] = 16,
    depthcloud: Annotated[
        str | None,
        typer.Option(
            metavar="DEPTH_TOPIC[,RGB_TOPIC]",
            help="Encode this depth (and colour) topic on /depthcloud_encoded (ros3djs).",
        ),
    ] = None,
    depthcloud_max_depth: Annotated[
        float, typer.Option(min=0.001, help="Metres per depth tile (near 0..d, far d..2d).")
    ] = 1.0,
    depthcloud_tile_size: Annotated[
        int, typer.Option(min=16, help="Side of each depth-cloud tile, pixels.")
    ] = 512,
    log_level: Annotated[LogLevel, typer.Option(help="Log level on stderr.")] = LogLevel.INFO,
    uvloop: Annotated[
        bool, typer.Option(help=f"Run on uvloop (install it with: {UVLOOP_EXTRA}).")
    ] = False,
    heap_keep: Annotated[
        int,
        typer.Option(
            min=0,
            help="MiB of freed heap kept for the next large message (glibc); 0: the "
            "system default, which maps and unmaps every buffer of a large message.",
        ),
    ] = HEAP_KEEP_MIB,
    handshake_timeout: Annotated[
        float,
        typer.Option(
            min=0.001, help="Seconds an accepted socket has to finish its TLS/WebSocket handshake."
        ),
    ] = 10.0,
    raise_fd_limit: Annotated[
        bool, typer.Option(help="Raise the soft RLIMIT_NOFILE to the hard limit at start-up.")
    ] = True,
    record: Annotated[
        Path | None, typer.Option(metavar="BAG", help="Record the graph's topics into this bag.")
    ] = None,
    record_topics: Annotated[
        str,
        typer.Option(callback=check_glob_list, metavar="PATTERNS", help="Topics --record records."),
    ] = "",
    record_regex: RegexOption = None,
    record_exclude_regex: ExcludeRegex = None,
    record_exclude_topics: ExcludeTopics = None,
    record_format: Format = BagFormat.MCAP,
    record_max_bag_size: MaxBagSize = None,
    record_max_bag_duration: MaxBagDuration = None,
    record_split_size: SplitSize = None,
    record_split_duration: SplitDuration = None,
    record_chunk_compression: ChunkCompressionOption = ChunkCompression.NONE,
    record_chunk_compression_level: ChunkCompressionLevel = None,
    record_repeat_latched: RepeatLatched = True,
    record_max_size: RecordMaxSize = None,
    record_split: RecordSplit = False,
    play: Annotated[
        list[Path] | None,
        typer.Option(metavar="BAG", help="Play this bag into the graph (repeat: split parts)."),
    ] = None,
    play_topics: Annotated[
        str, typer.Option(callback=check_glob_list, metavar="PATTERNS", help="Topics --play plays.")
    ] = "",
    rate: Rate = 1.0,
    loop: Loop = False,
    start_offset: StartOffset = 0.0,
    clock: Clock = None,
    play_check: Check = True,
    start_paused: StartPaused = False,
    remap: Remap = None,
    delay: Delay = 0.0,
    playback_duration: PlaybackDuration = None,
    playback_until_sec: PlaybackUntil = None,
    play_prefix: Prefix = "",
    wait_for_subscribers: WaitForSubscribers = False,
    wait_for_subscribers_timeout: WaitTimeout = None,
    zenoh: Annotated[
        bool, typer.Option(help=f"Share the graph over a Zenoh network ({ZENOH_EXTRA}).")
    ] = False,
    zenoh_config: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file, metavar="FILE", help="Zenoh's JSON5 config file."
        ),
    ] = None,
    zenoh_connect: Annotated[
        list[str] | None,
        typer.Option(metavar="ENDPOINT", help="Zenoh endpoint to connect to; repeatable."),
    ] = None,
    zenoh_listen: Annotated[
        list[str] | None,
        typer.Option(
            metavar="ENDPOINT",
            help="Zenoh endpoint to listen on (tcp/127.0.0.1:0 if none); repeatable.",
        ),
    ] = None,
    zenoh_mode: Annotated[
        ZenohMode, typer.Option(help="Join as a Zenoh peer, or as a client of a router.")
    ] = ZenohMode.PEER,
    zenoh_rmw_compat: Annotated[
        ZenohRmwCompat,
        typer.Option(
            help="rmw_zenoh's token defaults: 'current' (March 2025 on: empty durability is "
            "volatile) or 'pre-2025' (it is transient local)."
        ),
    ] = ZenohRmwCompat.CURRENT,
    zenoh_queue_bytes: Annotated[
        int,
        typer.Option(
            min=64 * 1024,
            metavar="BYTES",
            help="Bytes of Zenoh samples waiting to be handled; past it the oldest of the "
            "busiest topic are dropped. Also the largest Zenoh message accepted.",
        ),
    ] = MAX_QUEUED_BYTES,
    zenoh_max_entities: Annotated[
        int,
        typer.Option(
            min=1, help="Remote Zenoh entities (liveliness tokens) mirrored; more are ignored."
        ),
    ] = MAX_REMOTE_ENTITIES,
    domain_id: Annotated[
        int | None,
        typer.Option(min=0, help="ROS domain on Zenoh (default: ROS_DOMAIN_ID, else 0)."),
    ] = None,
    workers: Annotated[
        int,
        typer.Option(
            min=1,
            help="Server processes sharing the ports (SO_REUSEPORT, Linux) and one graph "
            "over Zenoh on loopback; restarted when they die.",
        ),
    ] = 1,
    reuse_port: Annotated[bool, typer.Option(hidden=True)] = False,
    ros2: Annotated[
        bool,
        typer.Option(
            help="Link the graph to ROS 2 through rclpy (ROS sourced, or pip install "
            "'rwt[ros2]'); ROS_DOMAIN_ID and the middleware come from the environment."
        ),
    ] = False,
    ros2_node_name: Annotated[
        str, typer.Option(help="Name of the rclpy node standing for the graph.")
    ] = "rwt",
    ros2_namespace: Annotated[str, typer.Option(help="Namespace of that node.")] = "/",
) -> None:
    """Run a rosbridge server on an in-memory graph until SIGINT or SIGTERM.

    Every transport asked for runs at once on one graph: WebSocket (--port), raw
    TCP (--tcp-port), UDP (--udp-port) and one session on stdin/stdout (--stdio).
    Options are named after rosbridge_server's parameters where one exists: port,
    address (--host here), max_message_size, use_compression
    (--websocket-compression), certfile, keyfile, topics_glob and the other globs.

    Logs go to stderr as key=value lines. stdout gets one "listening on URL" line
    per listener, the WebSocket one first, so scripts can use --port 0 (with
    --stdio, stdout carries the session and these lines go to stderr). With
    --video, a "video on http://HOST:PORT" line follows: image topics over HTTP
    on web_video_server's paths. --depthcloud DEPTH[,RGB] encodes a depth (and
    colour) topic for ros3djs, as depthcloud_encoder does. --record BAG records
    topics into a bag while serving; --play BAG publishes a bag's topics with
    their timing, pausable through the /rwt/player/* services.

    With --zenoh, several servers (and ROS 2 nodes on rmw_zenoh) share one graph:
    peers find each other through --zenoh-connect/--zenoh-listen endpoints or a
    router ('rwt router'); multicast scouting stays off. --workers N runs N such
    servers on the same ports, one graph, supervised by this process.

    With --ros2, an rclpy node (--ros2-node-name, default rwt) joins the ROS 2
    graph: its topics, services and nodes appear to rosbridge clients, and theirs
    to ROS 2 nodes (docs/ros2.md).

    A browser opening http://HOST:PORT/ (the WebSocket port) gets the web console:
    the live graph, echo, publish, calls, actions, images and TF.
    """
    dialect = dialect_for(dialect, play or (), record_format if record else None)
    if not (websocket or tcp_port is not None or udp_port is not None or stdio):
        raise usage_error(
            "nothing to serve: --no-websocket needs --tcp-port, --udp-port or --stdio"
        )
    check_tls(certfile, keyfile)
    secret = _secret_checked(auth_secret_file, bind_connection=auth_bind_connection)
    if uvloop and importlib.util.find_spec("uvloop") is None:
        _fail(f"--uvloop needs uvloop: {UVLOOP_EXTRA}")
    _set_up_process(log_level, heap_keep, raise_fd_limit)
    if (zenoh or workers > 1) and dialect is not Dialect.ROS2:
        raise usage_error("--zenoh and --workers speak rmw_zenoh's ROS 2 types: not --dialect ros1")
    if workers > 1:
        shared_only = not (stdio or udp_port is not None or video or video_port is not None)
        _serve_workers(
            workers,
            host=host,
            port=port if websocket else None,
            tcp_port=tcp_port,
            zenoh_mode=zenoh_mode,
            shared_only=shared_only,
        )
    zenoh_link = None
    if zenoh:
        zenoh_link = _zenoh_options(
            zenoh_mode, zenoh_connect, zenoh_listen, zenoh_config, domain_id, zenoh_rmw_compat
        )
        zenoh_link = replace(
            zenoh_link, queue_bytes=zenoh_queue_bytes, max_entities=zenoh_max_entities
        )
    ros2_link = _ros2_options(ros2_node_name, ros2_namespace, dialect, workers) if ros2 else None
    interface_dirs = list(interfaces or ())
    if ros2_link is not None:  # the robot's own definitions, after the user's
        interface_dirs += ros2_interface_dirs()
    graph = Graph(TypeRegistry(dialect, interface_dirs))
    origins = tuple(o.strip() for o in allowed_origins.split(",") if o.strip())
    site = _console_site(console, origins, url_path, certfile is not None, secret is not None)
    authenticator = (
        None
        if secret is None
        else rosauth_authenticator(secret, graph.clock, bind_connection=auth_bind_connection)
    )
    access = AccessPolicy(
        topics=parse_glob_list(topics_glob),
        services=parse_glob_list(services_glob),
        params=parse_glob_list(params_glob),
        actions=parse_glob_list(actions_glob),
    )
    config = ServerConfig(
        host=host,
        port=port if websocket else None,
        tcp_port=tcp_port,
        udp_port=udp_port,
        stdio=stdio,
        max_message_size=max_message_size,
        max_fragment_memory=max_fragment_memory,
        max_connections=max_connections,
        max_connections_per_host=max_connections_per_host,
        idle_timeout_s=idle_timeout or None,
        certfile=certfile,
        keyfile=keyfile,
        session=SessionConfig(
            status_level=StatusLevel.from_wire(status_level.value),
            send_buffer_limit=send_buffer_limit,
            send_timeout_s=send_timeout,
            hold_budget_s=hold_budget,
            access=access,
            max_pending_fragments=max_pending_fragments,
            fragment_timeout_s=fragment_timeout,
            max_queue_length=max_queue_length,
            call_timeout_s=call_timeout if call_timeout > 0 else None,
            max_subscriptions=max_subscriptions,
            max_advertisements=max_advertisements,
            max_pending_calls=max_pending_calls,
            max_pending_goals=max_pending_goals,
            auth_challenge=auth_bind_connection,
            png_inflate_rate=png_inflate_rate,
        ),
        websocket=WebSocketOptions(
            compression=websocket_compression,
            url_path=url_path,
            allowed_origins=origins,
            ping_interval_s=websocket_ping_interval,
            ping_timeout_s=websocket_ping_timeout,
            console=site,
        ),
        udp=UdpOptions(
            datagram_bytes=udp_datagram_size,
            idle_timeout_s=udp_idle_timeout,
            max_sessions=udp_max_sessions,
            max_sessions_per_host=udp_max_sessions_per_host,
            trust_source_address=udp_trust_source_address,
        ),
        tf=tf,
        handshake_timeout_s=handshake_timeout,
        reuse_port=reuse_port,
    )
    if site is not None:
        site.limits = _limits(config)
    server = RosbridgeServer(graph, config, authenticator=authenticator)
    if depthcloud:
        _depthcloud_encoder(graph, depthcloud, depthcloud_max_depth, depthcloud_tile_size)
    video_config = None
    if video or video_port is not None:  # a video port asks for the video server
        video_config = _video_config(
            host,
            VIDEO_PORT if video_port is None else video_port,
            video_max_connections,
            video_max_streams,
            site,
            graph if secret is not None else None,
        )
    jobs = bag_jobs(
        graph,
        record_options(
            record,
            topic_selection(
                record_topics,
                record_regex,
                record_exclude_regex,
                record_exclude_topics,
                prefix="record-",
            ),
            record_format,
            split_policy(
                record_max_bag_size,
                record_max_bag_duration,
                size_mb=record_split_size,
                duration_s=record_split_duration,
                prefix="record-",
            ),
            max_size=record_max_size,
            split_at_max=record_split,
            compression=chunk_compression(
                record_chunk_compression, record_chunk_compression_level, prefix="record-"
            ),
            repeat_latched=record_repeat_latched,
            prefix="record-",
        ),
        play_options(
            play,
            rate=rate,
            loop=loop,
            start_offset=start_offset,
            topics=play_topics,
            clock=clock,
            check=play_check,
            paused=start_paused,
            remap=remap,
            delay=delay,
            duration=playback_duration,
            until_sec=playback_until_sec,
            prefix=play_prefix,
            wait_for_subscribers=wait_for_subscribers,
            wait_timeout=wait_for_subscribers_timeout,
        ),
        command="serve",
    )
    freeze_startup_objects()
    try:
        anyio.run(
            _run,
            server,
            video_config,
            jobs,
            zenoh_link,
            ros2_link,
            backend_options={"use_uvloop": uvloop},
        )
    except (OSError, ValueError, ListenError, BaseExceptionGroup) as exc:
        message = _startup_error(exc)
        if message is None:
            raise
        _fail(message)


def _set_up_process(log_level: LogLevel, heap_keep_mib: int, raise_fd_limit: bool) -> None:
    """The server process's logging, allocator (``--heap-keep``) and descriptor limit."""
    logging.basicConfig(
        stream=sys.stderr,
        level=log_level.value.upper(),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    logging.getLogger("websockets").setLevel(logging.WARNING)  # we log connections ourselves
    if heap_keep_mib:
        tune_allocator(heap_keep_mib * 1024 * 1024)
    if raise_fd_limit:
        raise_nofile_limit()


def _depthcloud_encoder(graph: Graph, topics: str, max_depth: float, tile_size: int) -> None:
    """``--depthcloud DEPTH[,RGB]``: encode those topics for ros3djs on the graph."""
    # numpy and Pillow load only when asked for (benchmarks B11 base memory)
    from rwt_graph.media.depthcloud_node import DepthCloudEncoder  # noqa: PLC0415

    depth_topic, _, rgb_topic = topics.partition(",")
    DepthCloudEncoder(
        graph, depth_topic, rgb_topic or None, max_depth_per_tile=max_depth, tile_size=tile_size
    )


@app.command(short_help="Serve a bag's topics as a live robot.")
def play(
    bag: Annotated[list[Path], typer.Argument(help="The bag (several: split parts, as one).")],
    host: Annotated[str, typer.Option(help="Address the WebSocket server binds.")] = "127.0.0.1",
    port: Annotated[
        int, typer.Option(**PORT_RANGE, help="WebSocket port; 0 picks a free port.")
    ] = 9090,
    topics: Annotated[
        str,
        typer.Option(
            callback=check_glob_list, metavar="PATTERNS", help="Topics to play; default: all."
        ),
    ] = "",
    rate: Rate = 1.0,
    loop: Loop = False,
    start_offset: StartOffset = 0.0,
    clock: Clock = None,
    check: Check = True,
    start_paused: StartPaused = False,
    remap: Remap = None,
    delay: Delay = 0.0,
    playback_duration: PlaybackDuration = None,
    playback_until_sec: PlaybackUntil = None,
    prefix: Prefix = "",
    wait_for_subscribers: WaitForSubscribers = False,
    wait_for_subscribers_timeout: WaitTimeout = None,
    disable_keyboard_controls: DisableKeyboardControls = False,
    dialect: DialectOption = None,
    interfaces: Interfaces = None,
) -> None:
    """Serve a bag over rosbridge (WebSocket) with its original timing, then stop.

    Web clients see the bag as a live robot: TF through tf2_web_republisher,
    /tf_static and maps latched, rosapi. The /rwt/player/pause, resume, seek and
    get_status services control playback, and on a terminal the keys: space
    pauses and resumes, right arrow plays the next message, up/down the rate.
    Use 'rwt serve --play' for every server option (TCP, video, TLS...) and to
    keep serving after the end.
    """
    tune_allocator(HEAP_KEEP_MIB * 1024 * 1024)  # as rwt serve does: images, clouds
    graph = Graph(TypeRegistry(dialect_for(dialect, bag), interfaces or ()))
    server = RosbridgeServer(graph, ServerConfig(host=host, port=port))
    options = play_options(
        bag,
        rate=rate,
        loop=loop,
        start_offset=start_offset,
        topics=topics,
        clock=clock,
        check=check,
        paused=start_paused,
        remap=remap,
        delay=delay,
        duration=playback_duration,
        until_sec=playback_until_sec,
        prefix=prefix,
        wait_for_subscribers=wait_for_subscribers,
        wait_timeout=wait_for_subscribers_timeout,
    )
    keys = terminal_keys(disable_keyboard_controls)
    jobs = bag_jobs(graph, None, options, command="play", stop_at_end=server.stop, keyboard=keys)
    try:
        anyio.run(_run, server, None, jobs)
    except (OSError, ValueError, ListenError, BaseExceptionGroup, BagError) as exc:
        message = _startup_error(exc)
        if message is None:
            raise
        typer.echo(f"rwt play: {message}", err=True)
        raise typer.Exit(1) from None


def _serve_workers(
    count: int,
    *,
    host: str,
    port: int | None,
    tcp_port: int | None,
    zenoh_mode: ZenohMode,
    shared_only: bool,
) -> NoReturn:
    """``--workers N``: supervise N servers, then exit with their status."""
    if not shared_only:
        raise usage_error("--workers shares TCP ports: not with --stdio, --udp-port or --video")
    try:
        require_zenoh("--workers")
        status = run_workers(
            count, host=host, port=port, tcp_port=tcp_port, zenoh_mode=zenoh_mode.value
        )
    except (ValueError, OSError) as exc:
        _fail(str(exc))
    raise typer.Exit(status)


def _zenoh_options(
    mode: ZenohMode,
    connect: list[str] | None,
    listen: list[str] | None,
    config_file: Path | None,
    domain_id: int | None,
    rmw_compat: ZenohRmwCompat,
) -> ZenohOptions:
    try:
        return zenoh_options(
            mode=mode.value,
            connect=connect,
            listen=listen,
            config_file=config_file,
            domain_id=domain_id,
            rmw_compat=rmw_compat.value,
        )
    except ValueError as exc:
        _fail(str(exc))


def _secret_checked(path: Path | None, *, bind_connection: bool) -> str | None:
    """The rosauth secret of ``--auth-secret-file``, if given; usage error on a bad pair."""
    secret = None if path is None else _read_secret(path)
    if bind_connection and secret is None:
        raise usage_error("--auth-bind-connection needs --auth-secret-file")
    return secret


def _read_secret(path: Path) -> str:
    """The rosauth secret: the first line of ``path``, refused (exit 2) when empty."""
    try:
        lines = path.read_text("utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.reason if isinstance(exc, UnicodeDecodeError) else exc.strerror
        raise OptionError(
            f"cannot read {path}: {reason}", param_hint="--auth-secret-file"
        ) from None
    secret = lines[0].strip() if lines else ""
    if not secret:
        raise OptionError(f"the first line of {path} is empty", param_hint="--auth-secret-file")
    return secret


def _console_site(
    wanted: bool | None, origins: tuple[str, ...], url_path: str | None, tls: bool, auth: bool
) -> ConsoleSite | None:
    """The console of the WebSocket port, or None when it is off (docs/console.md).

    By default it is on, except with --allowed-origins: the operator chose which
    web pages may reach the robot, and the robot's own page is not one of them
    unless --console says so (its origin must then be allowed too). With
    --auth-secret-file it stays on: the page asks for the ``auth`` op first.
    """
    if wanted is None:
        wanted = not origins
    if not wanted:
        return None
    return ConsoleSite(websocket_path=url_path or "/", websocket_tls=tls, auth=auth)


def _limits(config: ServerConfig) -> dict[str, object]:
    """The limits the console lists, by option name (docs/limits.md)."""
    session = config.session
    return {
        "--max-message-size": config.max_message_size,
        "--max-connections": config.max_connections or "from the open-files limit",
        "--send-buffer-limit": session.send_buffer_limit,
        "--max-queue-length": session.max_queue_length,
        "--max-subscriptions": session.max_subscriptions,
        "--max-advertisements": session.max_advertisements,
        "--max-pending-calls": session.max_pending_calls,
        "--max-pending-goals": session.max_pending_goals,
        "--call-timeout": session.call_timeout_s or 0,
    }


def _video_config(
    host: str,
    port: int,
    max_connections: int,
    max_streams: int,
    site: ConsoleSite | None,
    tokens_on: Graph | None,
) -> VideoConfig:
    """The video server's settings.

    With ``tokens_on`` (--auth-secret-file) its streams need a token from that
    graph's ``/rwt/video_token`` (docs/video.md, D32).
    """
    # the video server (Pillow, numpy) loads only with --video (B11: base memory)
    from rwt_video import VideoConfig, VideoTokens, install_token_service  # noqa: PLC0415

    tokens = None
    if tokens_on is not None:
        tokens = VideoTokens()
        install_token_service(tokens_on, tokens)
        if site is not None:
            site.video_token = True
    console = None
    if site is not None:  # the same page under /console/; its WebSocket port is set in _run
        console = replace(site, root_is_console=False)
    return VideoConfig(
        host=host,
        port=port,
        max_connections=max_connections,
        max_streams=max_streams,
        console=console,
        tokens=tokens,
    )


def _ros2_options(node_name: str, namespace: str, dialect: Dialect, workers: int) -> Ros2Options:
    if dialect is not Dialect.ROS2:
        raise usage_error("--ros2 carries ROS 2 types: not --dialect ros1")
    if workers > 1:
        raise usage_error("--ros2 links one process's graph: not with --workers")
    try:
        return ros2_options(node_name, namespace)
    except ValueError as exc:
        _fail(str(exc))


def _fail(message: str) -> NoReturn:
    typer.echo(f"rwt serve: {message}", err=True)
    raise typer.Exit(1)


def _startup_error(exc: BaseException) -> str | None:
    """The one-line message of an error that stops ``rwt serve`` at start; None for a bug."""
    if isinstance(exc, BaseExceptionGroup):  # raised inside a task group
        messages = []
        for each in exc.exceptions:
            message = _startup_error(each)
            if message is None:
                return None
            messages.append(message)
        return "; ".join(messages)
    if isinstance(exc, ListenError | OSError | ValueError | BagError):  # SSLError: an OSError
        return str(exc)
    return None


def _unbound_listener(server: RosbridgeServer) -> tuple[str, str, int] | None:
    """The listener that failed to open: the first configured one without a URL.

    The server opens its listeners in this order and records each one's URL as it
    binds, so after an OSError the first one missing is the one that failed.
    """
    config = server.config
    listeners = (
        ("websocket", "WebSocket", config.port),
        ("tcp", "TCP", config.tcp_port),
        ("udp", "UDP", config.udp_port),
    )
    for key, name, port in listeners:
        if port is not None and key not in server.urls:
            return name, config.host, port
    return None


async def _run(
    server: RosbridgeServer,
    video: VideoConfig | None,
    jobs: BagJobs | None = None,
    zenoh: ZenohOptions | None = None,
    ros2: Ros2Options | None = None,
) -> None:
    out = sys.stderr if server.config.stdio else sys.stdout  # stdout is the stdio session

    def announce(url: str) -> None:
        print(f"listening on {url}", file=out, flush=True)

    async with (
        linked(server.graph, zenoh),
        linked_ros2(server.graph, ros2),
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(_stop_on_signal, server, tg.cancel_scope)
        if jobs is not None:  # a bag to play is checked before anything is served
            await tg.start(jobs.run)
        video_url = None
        if video is not None:
            from rwt_video import serve_video  # noqa: PLC0415 (see _video_config)

            try:
                video_url = await tg.start(serve_video, server.graph, video)
            except OSError as exc:
                raise ListenError("HTTP video", video.host, video.port, exc) from exc
            site = server.config.websocket.console
            if site is not None:  # the console on either port shows the streams
                site.video_port = urlsplit(video_url).port
            if video.console is not None:
                video.console.video_port = urlsplit(video_url).port

        async def serve(*, task_status: TaskStatus[str]) -> None:
            try:
                await server.serve(on_listening=announce, task_status=task_status)
            except OSError as exc:
                failed = _unbound_listener(server)
                if failed is None:
                    raise
                raise ListenError(*failed, exc) from exc
            tg.cancel_scope.cancel()  # stopped gracefully: the video server goes too

        await tg.start(serve)
        ws_url = server.urls.get("websocket")
        if video is not None and video.console is not None and ws_url:
            video.console.websocket_port = urlsplit(ws_url).port
        if video_url:
            print(f"video on {video_url}", file=out, flush=True)


async def _stop_on_signal(server: RosbridgeServer, scope: anyio.CancelScope) -> None:
    """First SIGINT/SIGTERM: stop gracefully; a second one: stop at once."""
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for signum in signals:
            logging.getLogger("rwt.server").info(
                "event=signal name=%s", signal.Signals(signum).name
            )
            if server._stop_requested:
                scope.cancel()
                return
            server.stop()


@app.command(short_help="Run a Zenoh router for rwt servers and ROS 2 nodes.")
def router(
    listen: Annotated[
        list[str] | None,
        typer.Option(metavar="ENDPOINT", help="Endpoint to listen on; repeatable."),
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(
            callback=check_readable_file, metavar="FILE", help="Zenoh's JSON5 config file."
        ),
    ] = None,
) -> None:
    """Run a Zenoh router until SIGINT or SIGTERM, from this install: no other binary.

    Servers started with 'rwt serve --zenoh --zenoh-mode client --zenoh-connect
    ENDPOINT' (and ROS 2 nodes on rmw_zenoh) meet through it. It listens on
    tcp/127.0.0.1:7447 unless told otherwise; give --listen tcp/0.0.0.0:7447 to
    let other machines in. stdout gets one "router listening on ENDPOINT" line per
    endpoint.
    """
    try:
        run_router(listen or ["tcp/127.0.0.1:7447"], config)
    except ValueError as exc:
        typer.echo(f"rwt router: {exc}", err=True)
        raise typer.Exit(1) from None


if __name__ == "__main__":  # python -m rwt_transports.cli
    app(prog_name="rwt")
