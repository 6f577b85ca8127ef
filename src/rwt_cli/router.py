"""``rwt router``: a Zenoh router for rwt servers and ROS 2 nodes, from this install."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .checks import check_readable_file
from .zenoh_link import run_router

__all__ = ["router"]


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
