"""The ``rwt`` command line.

``rwt serve`` runs a rosbridge server on an in-memory graph, on every transport
asked for at once (WebSocket, TCP, UDP, stdio; one graph, D22). Option names
follow rosbridge's parameters where one exists (``port``, ``address`` is
``--host`` here, ``max_message_size``, ``use_compression`` is
``--websocket-compression``, ``certfile``/``keyfile``, ``topics_glob``...). Logs
go to stderr as ``key=value`` lines; stdout gets one ``listening on URL`` line
per listener, the WebSocket one first, so scripts can use ``--port 0`` (with
``--stdio``, stdout is the session and those lines go to stderr). With ``--video``
a ``video on http://HOST:PORT`` line follows them (web_video_server's paths, port
8080 by default); ``--depthcloud DEPTH[,RGB]`` runs depthcloud_encoder's job on
the same graph.
"""

from __future__ import annotations

import importlib.util
import logging
import signal
import sys
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, NoReturn

import anyio
import typer
from anyio.abc import TaskStatus

from rwt_conformance.cli import conformance
from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.access import AccessPolicy, parse_glob_list
from rwt_protocol.levels import StatusLevel
from rwt_protocol.session import SessionConfig

from .allocator import tune_allocator
from .fdlimit import raise_nofile_limit
from .gcfreeze import freeze_startup_objects
from .server import RosbridgeServer, ServerConfig, rosauth_authenticator
from .udp import UdpOptions
from .websocket import WebSocketOptions

if TYPE_CHECKING:
    from rwt_video import VideoConfig

__all__ = ["app", "main"]

app = typer.Typer(no_args_is_help=True, add_completion=False, help=__doc__)

MiB = 1024 * 1024


class LevelName(StrEnum):
    """Status levels as the CLI accepts them."""

    NONE = "none"
    ERROR = "error"
    WARNING = "warning"
    INFO = "info"


class DialectName(StrEnum):
    """Dialects as the CLI accepts them."""

    ROS2 = "ros2"
    ROS1 = "ros1"


@app.callback()
def main() -> None:
    """rwt: a ROS-free rosbridge v2 server, client and conformance suite."""


app.command()(conformance)


@app.command()
def serve(
    host: Annotated[str, typer.Option(help="Address every listener binds.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="WebSocket port; 0 picks a free port.")] = 9090,
    websocket: Annotated[
        bool, typer.Option(help="Serve WebSocket on --port (--no-websocket: don't).")
    ] = True,
    tcp_port: Annotated[
        int | None, typer.Option(help="Also serve raw TCP on this port (0: a free one).")
    ] = None,
    udp_port: Annotated[
        int | None, typer.Option(help="Also serve UDP on this port (0: a free one).")
    ] = None,
    stdio: Annotated[
        bool, typer.Option(help="Also serve one session on stdin/stdout; stop when it ends.")
    ] = False,
    dialect: Annotated[DialectName, typer.Option(help="ROS message dialect.")] = DialectName.ROS2,
    interfaces: Annotated[
        list[Path] | None,
        typer.Option(help="Extra interface directory (<pkg>/msg|srv|action/...); repeatable."),
    ] = None,
    status_level: Annotated[
        LevelName, typer.Option(help="Status level of new connections.")
    ] = LevelName.ERROR,
    max_message_size: Annotated[
        int,
        typer.Option(
            help="Largest incoming message on every transport, also reassembled from parts, bytes."
        ),
    ] = 10 * MiB,
    max_pending_fragments: Annotated[
        int, typer.Option(min=1, help="Messages per connection whose fragments are arriving.")
    ] = 16,
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
    send_buffer_limit: Annotated[
        int,
        typer.Option(
            help="Outgoing bytes queued per connection (payload plus a fixed cost a frame)"
            " before dropping topic messages."
        ),
    ] = 16 * MiB,
    send_timeout: Annotated[
        float, typer.Option(help="Seconds a connection may stay over the send buffer limit.")
    ] = 30.0,
    max_connections: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Most simultaneous connections (all transports; a socket counts from accept)."
            " Default: the soft RLIMIT_NOFILE minus a reserve of min(128, limit/2) + 16.",
        ),
    ] = None,
    certfile: Annotated[
        Path | None, typer.Option(help="PEM certificate: TLS (wss, TLS over TCP).")
    ] = None,
    keyfile: Annotated[Path | None, typer.Option(help="PEM private key for --certfile.")] = None,
    auth_secret_file: Annotated[
        Path | None, typer.Option(help="rosauth secret (first line): clients must send auth first.")
    ] = None,
    topics_glob: Annotated[
        str, typer.Option(help="Allowed topics: fnmatch patterns, comma-separated.")
    ] = "",
    services_glob: Annotated[
        str, typer.Option(help="Allowed services (/rosapi/* always allowed).")
    ] = "",
    params_glob: Annotated[str, typer.Option(help="Allowed parameters.")] = "",
    actions_glob: Annotated[str, typer.Option(help="Allowed actions.")] = "",
    allowed_origins: Annotated[
        str, typer.Option(help="Accepted WebSocket Origin patterns, comma-separated (any).")
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
    video: Annotated[
        bool, typer.Option(help="Also serve image topics over HTTP (web_video_server).")
    ] = False,
    video_port: Annotated[int, typer.Option(help="HTTP port of --video; 0 picks one.")] = 8080,
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
    log_level: Annotated[str, typer.Option(help="Log level on stderr.")] = "info",
    uvloop: Annotated[
        bool, typer.Option(help="Run on uvloop (pip install 'rwt[bench]' or uvloop).")
    ] = False,
    heap_keep: Annotated[
        int,
        typer.Option(
            min=0,
            help="MiB of freed heap kept for the next large message (glibc); 0: the "
            "system default, which maps and unmaps every buffer of a large message.",
        ),
    ] = 64,
    handshake_timeout: Annotated[
        float,
        typer.Option(
            min=0.001, help="Seconds an accepted socket has to finish its TLS/WebSocket handshake."
        ),
    ] = 10.0,
    raise_fd_limit: Annotated[
        bool, typer.Option(help="Raise the soft RLIMIT_NOFILE to the hard limit at start-up.")
    ] = True,
) -> None:
    """Run a rosbridge server on an in-memory graph until SIGINT/SIGTERM."""
    logging.basicConfig(
        stream=sys.stderr,
        level=log_level.upper(),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    logging.getLogger("websockets").setLevel(logging.WARNING)  # we log connections ourselves
    if not (websocket or tcp_port is not None or udp_port is not None or stdio):
        _fail("nothing to serve: --no-websocket needs --tcp-port, --udp-port or --stdio")
    if heap_keep:
        tune_allocator(heap_keep * 1024 * 1024)
    if raise_fd_limit:
        raise_nofile_limit()
    graph = Graph(TypeRegistry(Dialect(dialect.value), interfaces or ()))
    authenticator = None
    if auth_secret_file is not None:
        try:
            secret = auth_secret_file.read_text("utf-8").splitlines()[0].strip()
        except (OSError, IndexError) as exc:
            _fail(f"cannot read --auth-secret-file: {exc}")
        if not secret:
            _fail("--auth-secret-file: the first line is empty")
        authenticator = rosauth_authenticator(secret, graph.clock)
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
        max_connections=max_connections,
        certfile=certfile,
        keyfile=keyfile,
        session=SessionConfig(
            status_level=StatusLevel.from_wire(status_level.value),
            send_buffer_limit=send_buffer_limit,
            send_timeout_s=send_timeout,
            access=access,
            max_message_size=max_message_size,
            max_pending_fragments=max_pending_fragments,
            fragment_timeout_s=fragment_timeout,
            max_queue_length=max_queue_length,
            call_timeout_s=call_timeout if call_timeout > 0 else None,
            max_subscriptions=max_subscriptions,
            max_advertisements=max_advertisements,
            max_pending_calls=max_pending_calls,
            max_pending_goals=max_pending_goals,
        ),
        websocket=WebSocketOptions(
            compression=websocket_compression,
            url_path=url_path,
            allowed_origins=tuple(o.strip() for o in allowed_origins.split(",") if o.strip()),
            ping_interval_s=websocket_ping_interval,
            ping_timeout_s=websocket_ping_timeout,
        ),
        udp=UdpOptions(
            datagram_bytes=udp_datagram_size,
            idle_timeout_s=udp_idle_timeout,
            max_sessions=udp_max_sessions,
            trust_source_address=udp_trust_source_address,
        ),
        tf=tf,
        handshake_timeout_s=handshake_timeout,
    )
    server = RosbridgeServer(graph, config, authenticator=authenticator)
    if depthcloud:
        # numpy and Pillow load only when asked for (benchmarks B11 base memory)
        from rwt_graph.media.depthcloud_node import DepthCloudEncoder  # noqa: PLC0415

        depth_topic, _, rgb_topic = depthcloud.partition(",")
        DepthCloudEncoder(
            graph,
            depth_topic,
            rgb_topic or None,
            max_depth_per_tile=depthcloud_max_depth,
            tile_size=depthcloud_tile_size,
        )
    video_config = (
        _video_config(host, video_port, video_max_connections, video_max_streams) if video else None
    )
    if uvloop and importlib.util.find_spec("uvloop") is None:
        _fail("--uvloop needs the uvloop package")
    freeze_startup_objects()
    try:
        anyio.run(_run, server, video_config, backend_options={"use_uvloop": uvloop})
    except (OSError, ValueError) as exc:  # ssl.SSLError is an OSError
        _fail(str(exc))
    except BaseExceptionGroup as group:  # the same, raised inside the task group
        startup, rest = group.split((OSError, ValueError))
        if startup is None or rest is not None:
            raise
        _fail("; ".join(str(exc) for exc in startup.exceptions))


def _video_config(host: str, port: int, max_connections: int, max_streams: int) -> VideoConfig:
    # the video server (Pillow, numpy) loads only with --video (B11: base memory)
    from rwt_video import VideoConfig  # noqa: PLC0415

    return VideoConfig(
        host=host, port=port, max_connections=max_connections, max_streams=max_streams
    )


def _fail(message: str) -> NoReturn:
    typer.echo(f"rwt serve: {message}", err=True)
    raise typer.Exit(1)


async def _run(server: RosbridgeServer, video: VideoConfig | None) -> None:
    out = sys.stderr if server.config.stdio else sys.stdout  # stdout is the stdio session

    def announce(url: str) -> None:
        print(f"listening on {url}", file=out, flush=True)

    async with anyio.create_task_group() as tg:
        tg.start_soon(_stop_on_signal, server, tg.cancel_scope)
        video_url = None
        if video is not None:
            from rwt_video import serve_video  # noqa: PLC0415 (see _video_config)

            video_url = await tg.start(serve_video, server.graph, video)

        async def serve(*, task_status: TaskStatus[str]) -> None:
            await server.serve(on_listening=announce, task_status=task_status)
            tg.cancel_scope.cancel()  # stopped gracefully: the video server goes too

        await tg.start(serve)
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
