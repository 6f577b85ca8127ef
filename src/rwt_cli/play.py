"""``rwt play``: a bag's topics served over rosbridge as a live robot, then stop."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import anyio
import typer

from rwt_graph.graph import Graph
from rwt_graph.types import TypeRegistry
from rwt_transports.process.allocator import HEAP_KEEP_MIB, tune_allocator
from rwt_transports.server import GraphServer, ServerConfig

from .bag_options import (
    Check,
    Clock,
    Delay,
    DialectOption,
    DisableKeyboardControls,
    Interfaces,
    Loop,
    PlaybackDuration,
    PlaybackUntil,
    Prefix,
    Rate,
    Remap,
    StartOffset,
    StartPaused,
    WaitForSubscribers,
    WaitTimeout,
    bag_jobs,
    dialect_for,
    play_options,
    terminal_keys,
)
from .checks import check_glob_list, one_line_errors
from .options import PORT_RANGE
from .running import STARTUP_ERRORS, run_server

__all__ = ["play"]


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
    server = GraphServer(graph, ServerConfig(host=host, port=port))
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
    with one_line_errors("play", STARTUP_ERRORS):
        anyio.run(run_server, server, None, jobs)
