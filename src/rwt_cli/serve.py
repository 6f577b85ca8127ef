"""``rwt serve``: every transport asked for, on one in-memory graph (D22).

The options are in ``serve_options`` (a group a help section); this module checks
their combinations, builds the graph, the ``ServerConfig``, the links and the bag
jobs, and runs them. Its help text, the docstring of ``serve``, is what users
read: it names no internal documents. Bad option values are refused at start
with a one-line usage error (exit code 2, see ``checks``); an address that
cannot be bound names its listener (exit 1).
"""

from __future__ import annotations

import importlib.util
import logging
import math
import sys
from dataclasses import replace
from functools import partial
from typing import TYPE_CHECKING, NoReturn

import anyio
import typer

from rwt_console import ConsoleSite, console_for
from rwt_graph.graph import Graph
from rwt_graph.safety.envelope import Envelope
from rwt_graph.safety.rules import RulesError, SafetyRules, load_rules
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.access import AccessPolicy, parse_glob_list, parse_split_glob
from rwt_protocol.server.session import SessionConfig
from rwt_transports.foxglove import FoxgloveOptions
from rwt_transports.http.mcp_options import McpOptions
from rwt_transports.http.mcp_siblings import McpSiblings
from rwt_transports.process.allocator import tune_allocator
from rwt_transports.process.fdlimit import raise_nofile_limit
from rwt_transports.process.gcfreeze import freeze_startup_objects
from rwt_transports.server import GraphServer, ServerConfig, rosauth_authenticator
from rwt_transports.udp.transport import UdpOptions
from rwt_transports.webrtc.ice import parse_ice_servers
from rwt_transports.webrtc.native import native_ice_refusal
from rwt_transports.webrtc.signalling import WebRtcOptions
from rwt_transports.websocket import WebSocketOptions
from rwt_transports.workers.counts import ConnectionCountWriter
from rwt_transports.workers.placement import Placement
from rwt_transports.workers.supervisor import parse_listen_fds, run_workers

from .bag_options import (
    bag_jobs,
    chunk_compression,
    dialect_for,
    play_options,
    record_options,
    split_policy,
    topic_selection,
)
from .checks import OptionError, check_tls, one_line_errors, usage_error
from .groups import grouped_command
from .options import MCP_EXTRA, UVLOOP_EXTRA, VIDEO_PORT, WEBRTC_EXTRA
from .ros2_link import ros2_interface_dirs, ros2_options
from .running import STARTUP_ERRORS, run_server
from .serve_options import PlacementMode, ServeOptions
from .zenoh_link import require_zenoh, zenoh_options

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from rwt_bag.jobs import BagJobs
    from rwt_ros2 import Ros2Options
    from rwt_video import VideoConfig, VideoTokens
    from rwt_zenoh.config import ZenohOptions

    from .serve_options import Media, PlayOptions, Process, RecordOptions, ScaleOut

__all__ = ["serve"]


@grouped_command(ServeOptions)
def serve(options: ServeOptions) -> None:
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
    record = options.record
    dialect = dialect_for(
        options.graph.dialect,
        options.play.play or (),
        record.record_format if record.record else None,
    )
    _check_listeners(options)
    check_tls(options.security.certfile, options.security.keyfile)
    secret = _secret_checked(
        options.security.auth_secret_file, options.security.auth_bind_connection
    )
    if options.process.uvloop and importlib.util.find_spec("uvloop") is None:
        fail(f"--uvloop needs uvloop: {UVLOOP_EXTRA}")
    if options.listeners.webrtc and importlib.util.find_spec("aiortc") is None:
        fail(f"--webrtc needs aiortc: {WEBRTC_EXTRA}")
    if options.listeners.mcp and importlib.util.find_spec("mcp") is None:
        fail(f"--mcp needs the MCP SDK: {MCP_EXTRA}")
    interface_dirs = list(options.graph.interfaces or ())
    if options.ros2.ros2:  # the robot's own definitions, after the user's
        interface_dirs += ros2_interface_dirs()
    registry = TypeRegistry(dialect, interface_dirs)
    safety = _safety_rules(options.security.safety, registry)  # before the logs: one line
    _set_up_process(options.process)
    scale_out = options.scale_out
    if (scale_out.zenoh or scale_out.workers > 1) and dialect is not Dialect.ROS2:
        raise usage_error("--zenoh and --workers speak rmw_zenoh's ROS 2 types: not --dialect ros1")
    if scale_out.placement is not PlacementMode.NONE and _alone(scale_out):
        raise usage_error("--placement places connections among workers: add --workers N")
    if scale_out.workers > 1:
        _serve_workers(options)  # each worker reads --safety again
    zenoh_link = _zenoh_options(scale_out) if scale_out.zenoh else None
    ros2_link = _ros2_options(options, dialect) if options.ros2.ros2 else None
    graph = Graph(registry, safety=safety)  # the rules fit its types: checked above
    tokens = _video_tokens(options, graph) if secret is not None else None
    server = _server(options, graph, secret, tokens)
    media = options.media
    if media.depthcloud:
        _depthcloud_encoder(graph, media)
    video = _video_config(options, server.console, tokens)
    jobs = _bag_jobs(graph, options.record, options.play)
    freeze_startup_objects()
    _run(server, video, jobs, zenoh_link, ros2_link, options.process)


def _check_listeners(options: ServeOptions) -> None:
    """Refuse no listener at all, WebRTC without its port, ICE servers without WebRTC."""
    listeners = options.listeners
    if not (
        listeners.websocket
        or listeners.tcp_port is not None
        or listeners.udp_port is not None
        or listeners.stdio
    ):
        raise usage_error(
            "nothing to serve: --no-websocket needs --tcp-port, --udp-port or --stdio"
        )
    if listeners.webrtc and not listeners.websocket:
        raise usage_error("--webrtc answers on the WebSocket port: not with --no-websocket")
    if listeners.webrtc_stack != "auto" and not listeners.webrtc:
        raise usage_error("--webrtc-stack chooses --webrtc's stack: add --webrtc")
    if listeners.ice_server and not listeners.webrtc:
        raise usage_error("--ice-server gives --webrtc its STUN and TURN servers: add --webrtc")
    if listeners.webrtc_stack == "native" and (
        refused := native_ice_refusal(parse_ice_servers(listeners.ice_server or ()))
    ):
        raise usage_error(f"--webrtc-stack native: {refused}")
    if listeners.mcp and not listeners.websocket:
        raise usage_error("--mcp answers on the WebSocket port: not with --no-websocket")
    if listeners.mcp_read_only and not listeners.mcp:
        raise usage_error("--mcp-read-only is a setting of --mcp: add --mcp")
    if listeners.mcp_authorization_server is not None:
        if not listeners.mcp:
            raise usage_error("--mcp-authorization-server is a setting of --mcp: add --mcp")
        if not listeners.mcp_authorization_server.startswith(("https://", "http://")):
            raise usage_error("--mcp-authorization-server: an issuer URL, https://HOST[/PATH]")


def _set_up_process(process: Process) -> None:
    """The server process's logging, allocator (``--heap-keep``) and descriptor limit."""
    logging.basicConfig(
        stream=sys.stderr,
        level=process.log_level.value.upper(),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    logging.getLogger("websockets").setLevel(logging.WARNING)  # we log connections ourselves
    if process.heap_keep:
        tune_allocator(process.heap_keep * 1024 * 1024)
    if process.raise_fd_limit:
        raise_nofile_limit()


def _server(
    options: ServeOptions, graph: Graph, secret: str | None, tokens: VideoTokens | None
) -> GraphServer:
    """The server of the options on ``graph``, its console listing its limits.

    ``tokens``: the video tokens an offer's ``Authorization: Bearer`` may carry (--webrtc),
    and a new MCP session's (--mcp).
    """
    security = options.security
    origins = tuple(o.strip() for o in security.allowed_origins.split(",") if o.strip())
    site = console_for(
        options.media.console,
        origins,
        options.listeners.url_path,
        tls=security.certfile is not None,
        auth=secret is not None,
        foxglove=options.listeners.foxglove,
    )
    config = _server_config(options, origins, site)
    if options.listeners.webrtc:  # an offer's bearer token is a video token (docs/webrtc.md)
        check = None if tokens is None else tokens.valid
        ice_servers = tuple(options.listeners.ice_server or ())
        stack = options.listeners.webrtc_stack
        webrtc = WebRtcOptions(bearer_token=check, ice_servers=ice_servers, stack=stack)
        config = replace(config, webrtc=webrtc)
    if options.listeners.mcp:  # a new MCP session's bearer token is a video token (docs/mcp.md)
        check = None if tokens is None else tokens.valid
        mcp = McpOptions(
            read_only=options.listeners.mcp_read_only,
            bearer_token=check,
            authorization_server=options.listeners.mcp_authorization_server,
            video_port=_video_port(options),
            siblings=_siblings(options.scale_out.worker_state),
        )
        config = replace(config, mcp=mcp)
    if not options.listeners.http_api:  # docs/http.md
        config = replace(config, http_options={"http": None})
    if tokens is not None:  # an HTTP API request's bearer token is a video token (docs/http.md)
        config = replace(config, bearer_token=tokens.valid)
    if site is not None:
        site.limits = _limits(config)
    authenticator = (
        None
        if secret is None
        else rosauth_authenticator(
            secret, graph.clock, bind_connection=security.auth_bind_connection
        )
    )
    return GraphServer(graph, config, authenticator=authenticator)


def _server_config(
    options: ServeOptions, origins: tuple[str, ...], site: ConsoleSite | None
) -> ServerConfig:
    """``ServerConfig`` of the listener, security and limit options."""
    listeners, security, limits = options.listeners, options.security, options.limits
    return ServerConfig(
        host=listeners.host,
        port=listeners.port if listeners.websocket else None,
        tcp_port=listeners.tcp_port,
        udp_port=listeners.udp_port,
        stdio=listeners.stdio,
        max_message_size=limits.max_message_size,
        max_fragment_memory=limits.max_fragment_memory,
        memory_budget=limits.memory_budget,
        max_connections=limits.max_connections,
        max_connections_per_host=limits.max_connections_per_host,
        host_prefix_v4=limits.host_prefix_v4,
        host_prefix_v6=limits.host_prefix_v6,
        idle_timeout_s=limits.idle_timeout or None,
        certfile=security.certfile,
        keyfile=security.keyfile,
        session=_session_config(options),
        websocket=WebSocketOptions(
            compression=listeners.websocket_compression,
            url_path=listeners.url_path,
            allowed_origins=origins,
            ping_interval_s=listeners.websocket_ping_interval,
            ping_timeout_s=listeners.websocket_ping_timeout,
            console=site,
        ),
        foxglove=FoxgloveOptions(
            on_rosbridge_port=listeners.foxglove,
            port=listeners.foxglove_port,
            assets=listeners.assets,
            package_paths=tuple(listeners.package_path or ()),
            show_plumbing=listeners.foxglove_show_plumbing,
        ),
        udp=UdpOptions(
            datagram_bytes=listeners.udp_datagram_size,
            idle_timeout_s=limits.udp_idle_timeout,
            max_sessions=limits.udp_max_sessions,
            max_sessions_per_host=limits.udp_max_sessions_per_host,
            trust_source_address=security.udp_trust_source_address,
        ),
        tf=options.graph.tf,
        use_sim_time=options.graph.use_sim_time,
        handshake_timeout_s=limits.handshake_timeout,
        reuse_port=options.scale_out.reuse_port,
        listen_fds=parse_listen_fds(options.scale_out.listen_fd or ()),
        on_connections=_worker_counter(options.scale_out.worker_state),
        placement=_placement(options.scale_out),
    )


def _alone(scale_out: ScaleOut) -> bool:
    """Whether this server is neither the parent of workers nor one (``--worker-state``)."""
    return scale_out.workers == 1 and scale_out.worker_state is None


def _placement(scale_out: ScaleOut) -> Placement | None:
    """A worker's place for ``--placement topic`` (D57); None: connections stay."""
    state = scale_out.worker_state
    if scale_out.placement is not PlacementMode.TOPIC or state is None:
        return None
    return Placement.of_state(state, scale_out.worker_count)


def _siblings(state: str | None) -> McpSiblings | None:
    """A worker's place among the others, whose MCP sessions and tasks it reaches."""
    return None if state is None else McpSiblings.of_state(state)


def _worker_counter(path: str | None) -> Callable[[int], None] | None:
    """A worker's connection count, kept where its parent reads it (``worker_counts``).

    A file that cannot be mapped costs the parent's log its count, not the worker.
    """
    if path is None:
        return None
    try:
        return ConnectionCountWriter(path).write
    except OSError as exc:
        logging.getLogger("rwt.workers").warning("event=worker_state_unavailable error=%r", exc)
        return None


def _session_config(options: ServeOptions) -> SessionConfig:
    """``SessionConfig`` of a connection: its status level, access and limits."""
    security, limits = options.security, options.limits
    return SessionConfig(
        status_level=StatusLevel.from_wire(options.graph.status_level.value),
        compat=options.graph.compat,
        send_buffer_limit=limits.send_buffer_limit,
        send_timeout_s=limits.send_timeout,
        hold_budget_s=limits.hold_budget,
        access=AccessPolicy(
            topics=parse_glob_list(security.topics_glob),
            topics_pub=parse_split_glob(security.topics_pub_glob),
            topics_sub=parse_split_glob(security.topics_sub_glob),
            services=parse_glob_list(security.services_glob),
            params=parse_glob_list(security.params_glob),
            actions=parse_glob_list(security.actions_glob),
        ),
        max_pending_fragments=limits.max_pending_fragments,
        fragment_timeout_s=limits.fragment_timeout,
        max_queue_length=limits.max_queue_length,
        call_timeout_s=limits.call_timeout if limits.call_timeout > 0 else None,
        max_subscriptions=limits.max_subscriptions,
        max_advertisements=limits.max_advertisements,
        max_pending_calls=limits.max_pending_calls,
        max_pending_goals=limits.max_pending_goals,
        auth_challenge=security.auth_bind_connection,
        png_inflate_rate=limits.png_inflate_rate,
        qos_lifespan_s=limits.qos_lifespan if limits.qos_lifespan > 0 else math.inf,
    )


def _bag_jobs(graph: Graph, record: RecordOptions, play: PlayOptions) -> BagJobs | None:
    """The ``--record`` and ``--play`` jobs, or None without either."""
    return bag_jobs(
        graph,
        record_options(
            record.record,
            topic_selection(
                record.record_topics,
                record.record_regex,
                record.record_exclude_regex,
                record.record_exclude_topics,
                prefix="record-",
            ),
            record.record_format,
            split_policy(
                record.record_max_bag_size,
                record.record_max_bag_duration,
                size_mb=record.record_split_size,
                duration_s=record.record_split_duration,
                prefix="record-",
            ),
            max_size=record.record_max_size,
            split_at_max=record.record_split,
            compression=chunk_compression(
                record.record_chunk_compression,
                record.record_chunk_compression_level,
                prefix="record-",
            ),
            repeat_latched=record.record_repeat_latched,
            prefix="record-",
        ),
        play_options(
            play.play,
            rate=play.rate,
            loop=play.loop,
            start_offset=play.start_offset,
            topics=play.play_topics,
            clock=play.clock,
            check=play.play_check,
            paused=play.start_paused,
            remap=play.remap,
            delay=play.delay,
            duration=play.playback_duration,
            until_sec=play.playback_until_sec,
            prefix=play.play_prefix,
            wait_for_subscribers=play.wait_for_subscribers,
            wait_timeout=play.wait_for_subscribers_timeout,
        ),
        command="serve",
    )


def _run(
    server: GraphServer,
    video: VideoConfig | None,
    jobs: BagJobs | None,
    zenoh: ZenohOptions | None,
    ros2: Ros2Options | None,
    process: Process,
) -> None:
    """Serve until a signal; a start-up error is one line (exit 1)."""
    serve = partial(run_server, heap_trim_s=process.heap_trim)
    with one_line_errors("serve", STARTUP_ERRORS):
        anyio.run(
            serve, server, video, jobs, zenoh, ros2, backend_options={"use_uvloop": process.uvloop}
        )


def _depthcloud_encoder(graph: Graph, media: Media) -> None:
    """``--depthcloud DEPTH[,RGB]``: encode those topics for ros3djs on the graph."""
    # numpy and Pillow load only when asked for (benchmarks B11 base memory)
    from rwt_graph.media.depthcloud_node import DepthCloudEncoder  # noqa: PLC0415

    depth_topic, _, rgb_topic = (media.depthcloud or "").partition(",")
    DepthCloudEncoder(
        graph,
        depth_topic,
        rgb_topic or None,
        max_depth_per_tile=media.depthcloud_max_depth,
        tile_size=media.depthcloud_tile_size,
    )


def _serve_workers(options: ServeOptions) -> NoReturn:
    """``--workers N``: supervise N servers, then exit with their status."""
    listeners, media, scale_out = options.listeners, options.media, options.scale_out
    if (
        listeners.stdio
        or listeners.udp_port is not None
        or media.video
        or media.video_port is not None
    ):
        raise usage_error("--workers shares TCP ports: not with --stdio, --udp-port or --video")
    try:
        require_zenoh("--workers")
        status = run_workers(
            scale_out.workers,
            host=listeners.host,
            port=listeners.port if listeners.websocket else None,
            tcp_port=listeners.tcp_port,
            zenoh_mode=scale_out.zenoh_mode.value,
        )
    except (ValueError, OSError) as exc:
        fail(str(exc))
    raise typer.Exit(status)


def _zenoh_options(scale_out: ScaleOut) -> ZenohOptions:
    """The ``--zenoh`` link's options; a bad endpoint or config exits with one line."""
    try:
        link = zenoh_options(
            mode=scale_out.zenoh_mode.value,
            connect=scale_out.zenoh_connect,
            listen=scale_out.zenoh_listen,
            config_file=scale_out.zenoh_config,
            domain_id=scale_out.domain_id,
            rmw_compat=scale_out.zenoh_rmw_compat.value,
        )
    except ValueError as exc:
        fail(str(exc))
    return replace(
        link,
        queue_bytes=scale_out.zenoh_queue_bytes,
        outbox_bytes=scale_out.zenoh_outbox_bytes,
        max_entities=scale_out.zenoh_max_entities,
    )


def _safety_rules(path: Path | None, registry: TypeRegistry) -> SafetyRules | None:
    """The rules of ``--safety FILE``, checked against ``registry``'s types.

    Raises:
        OptionError: the file does not parse, or a rule does not fit the types
            (exit 2, the message naming the file's line).
    """
    if path is None:
        return None
    try:
        rules = load_rules(path)
        Envelope(rules, registry)  # the types, fields and stops, as the graph will check them
    except RulesError as exc:
        raise OptionError(exc.message, param_hint="--safety") from None
    return rules


def _secret_checked(path: Path | None, bind_connection: bool) -> str | None:
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


def _limits(config: ServerConfig) -> dict[str, object]:
    """The limits the console lists, by option name (docs/limits.md)."""
    session = config.session
    return {
        "--max-message-size": config.max_message_size,
        "--max-connections": config.max_connections or "from the open-files limit",
        "--send-buffer-limit": session.send_buffer_limit,
        "--max-queue-length": session.max_queue_length,
        "--qos-lifespan": "none" if math.isinf(session.qos_lifespan_s) else session.qos_lifespan_s,
        "--max-subscriptions": session.max_subscriptions,
        "--max-advertisements": session.max_advertisements,
        "--max-pending-calls": session.max_pending_calls,
        "--max-pending-goals": session.max_pending_goals,
        "--call-timeout": session.call_timeout_s or 0,
    }


def _video_tokens(options: ServeOptions, graph: Graph) -> VideoTokens | None:
    """With --auth-secret-file: the tokens of ``/rwt/video_token`` on ``graph``, if used.

    The video server's streams (docs/video.md, D32) and WebRTC offers
    (docs/webrtc.md), MCP sessions (docs/mcp.md) and HTTP API requests (docs/http.md)
    take them; None without --video, --video-port, --webrtc, --mcp or the HTTP API.
    """
    media = options.media
    listeners = options.listeners
    wanted = (media.video, media.video_port is not None, listeners.webrtc, listeners.mcp)
    if not (any(wanted) or listeners.http_api):
        return None
    # the video package (Pillow, numpy) loads only when used (B11: base memory)
    from rwt_video import VideoTokens, install_token_service  # noqa: PLC0415

    tokens = VideoTokens()
    install_token_service(graph, tokens)
    return tokens


def _video_port(options: ServeOptions) -> int | None:
    """The video server's port where it is known before it listens (not ``--video-port 0``)."""
    media = options.media
    if not media.video and media.video_port is None:
        return None
    port = VIDEO_PORT if media.video_port is None else media.video_port
    return port or None


def _video_config(
    options: ServeOptions, site: ConsoleSite | None, tokens: VideoTokens | None
) -> VideoConfig | None:
    """The video server of ``--video``/``--video-port``, or None without them.

    With ``tokens`` (--auth-secret-file, ``_video_tokens``) its streams need a token
    from the graph's ``/rwt/video_token`` (docs/video.md, D32).
    """
    media = options.media
    if not media.video and media.video_port is None:  # a video port asks for the video server
        return None
    # the video server (Pillow, numpy) loads only with --video (B11: base memory)
    from rwt_video import VideoConfig  # noqa: PLC0415

    if tokens is not None and site is not None:
        site.video_token = True
    console = None
    if site is not None:  # the same page under /console/; its WebSocket port is set later
        console = replace(site, root_is_console=False)
    return VideoConfig(
        host=options.listeners.host,
        port=VIDEO_PORT if media.video_port is None else media.video_port,
        max_connections=media.video_max_connections,
        max_streams=media.video_max_streams,
        console=console,
        tokens=tokens,
    )


def _ros2_options(options: ServeOptions, dialect: Dialect) -> Ros2Options:
    """The ``--ros2`` link's options; usage error with ROS 1 types or ``--workers``."""
    if dialect is not Dialect.ROS2:
        raise usage_error("--ros2 carries ROS 2 types: not --dialect ros1")
    if options.scale_out.workers > 1:
        raise usage_error("--ros2 links one process's graph: not with --workers")
    try:
        return ros2_options(options.ros2.ros2_node_name, options.ros2.ros2_namespace)
    except ValueError as exc:
        fail(str(exc))


def fail(message: str) -> NoReturn:
    """Exit 1 with ``rwt serve: MESSAGE`` on stderr."""
    typer.echo(f"rwt serve: {message}", err=True)
    raise typer.Exit(1)
