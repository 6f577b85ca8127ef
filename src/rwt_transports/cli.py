"""The ``rwt`` command line.

``rwt serve`` runs a rosbridge server on an in-memory graph. Option names follow
rosbridge_websocket's parameters where one exists (``port``, ``address`` is
``--host`` here as issue 2 asks, ``max_message_size``, ``use_compression`` is
``--websocket-compression``). Logs go to stderr; the first stdout line is
``listening on ws://HOST:PORT`` so scripts can use ``--port 0``.
"""

from __future__ import annotations

import dataclasses
import logging
import signal
import sys
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import anyio
import typer

from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.levels import StatusLevel
from rwt_protocol.session import SessionConfig

from .conformance.cli import conformance
from .server import RosbridgeServer, ServerConfig
from .websocket import WebSocketOptions

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
    host: Annotated[str, typer.Option(help="Address to bind.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="WebSocket port; 0 picks a free port.")] = 9090,
    dialect: Annotated[DialectName, typer.Option(help="ROS message dialect.")] = DialectName.ROS2,
    interfaces: Annotated[
        list[Path] | None,
        typer.Option(help="Extra interface directory (<pkg>/msg|srv|action/...); repeatable."),
    ] = None,
    status_level: Annotated[
        LevelName, typer.Option(help="Status level of new connections.")
    ] = LevelName.ERROR,
    max_message_size: Annotated[
        int, typer.Option(help="Largest incoming message, also reassembled from parts, bytes.")
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
    send_buffer_limit: Annotated[
        int, typer.Option(help="Outgoing bytes queued per connection before dropping.")
    ] = 16 * MiB,
    call_timeout: Annotated[
        float, typer.Option(help="Seconds a call_service without timeout may wait; 0 = no limit.")
    ] = 30.0,
    websocket_compression: Annotated[bool, typer.Option(help="Offer permessage-deflate.")] = False,
    url_path: Annotated[
        str | None, typer.Option(help="Only accept WebSocket connections on this path.")
    ] = None,
    tf: Annotated[
        bool,
        typer.Option(help="Offer tf2_web_republisher (/tf2_web_republisher, /republish_tfs)."),
    ] = True,
    log_level: Annotated[str, typer.Option(help="Log level on stderr.")] = "info",
) -> None:
    """Run a rosbridge server on an in-memory graph until Ctrl-C."""
    logging.basicConfig(
        stream=sys.stderr,
        level=log_level.upper(),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    logging.getLogger("websockets").setLevel(logging.WARNING)  # we log connections ourselves
    registry = TypeRegistry(Dialect(dialect.value), interfaces or ())
    config = ServerConfig(
        host=host,
        port=port,
        session=SessionConfig(
            status_level=StatusLevel.from_wire(status_level.value),
            send_buffer_limit=send_buffer_limit,
            max_message_size=max_message_size,
            max_pending_fragments=max_pending_fragments,
            fragment_timeout_s=fragment_timeout,
            max_queue_length=max_queue_length,
            call_timeout_s=call_timeout if call_timeout > 0 else None,
        ),
        websocket=WebSocketOptions(
            max_message_size=max_message_size,
            compression=websocket_compression,
            url_path=url_path,
        ),
    )
    config = dataclasses.replace(config, tf=tf)
    server = RosbridgeServer(Graph(registry), config)
    try:
        anyio.run(_run, server)
    except OSError as exc:
        typer.echo(f"rwt serve: {exc}", err=True)
        raise typer.Exit(1) from None


async def _run(server: RosbridgeServer) -> None:
    def announce(url: str) -> None:
        print(f"listening on {url}", flush=True)

    async with anyio.create_task_group() as tg:
        tg.start_soon(_stop_on_signal, tg.cancel_scope)
        await server.serve(on_listening=announce)


async def _stop_on_signal(scope: anyio.CancelScope) -> None:
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for signum in signals:
            logging.getLogger("rwt.server").info("stopping on %s", signal.Signals(signum).name)
            scope.cancel()
            return
