"""Running a server from the command line (``rwt serve``, ``rwt play``).

``run_server`` serves until a signal: the bag jobs first, then the video server,
then the listeners, each announced on stdout. Errors that stop a start-up
(``STARTUP_ERRORS``: a port in use, a bad bag) become one line through
``checks.one_line_errors``.
"""

from __future__ import annotations

import logging
import signal
import sys
from typing import TYPE_CHECKING, TextIO
from urllib.parse import urlsplit

import anyio

from rwt_bag.errors import BagError
from rwt_transports.listen import ListenError
from rwt_transports.process.allocator import keep_trimmed

from .ros2_link import linked_ros2
from .zenoh_link import linked

if TYPE_CHECKING:
    from anyio.abc import TaskGroup, TaskStatus

    from rwt_bag.jobs import BagJobs
    from rwt_ros2 import Ros2Options
    from rwt_transports.server import GraphServer
    from rwt_video import VideoConfig
    from rwt_zenoh.config import ZenohOptions

__all__ = ["STARTUP_ERRORS", "run_server"]

STARTUP_ERRORS: tuple[type[BaseException], ...] = (OSError, ValueError, BagError)
"""What stops a server's start that the user can fix: ``ListenError`` and ``SSLError``
(``OSError``s), a bad option value (``ValueError``, ``ConfigError``), a bad bag."""


async def run_server(
    server: GraphServer,
    video: VideoConfig | None,
    jobs: BagJobs | None = None,
    zenoh: ZenohOptions | None = None,
    ros2: Ros2Options | None = None,
    *,
    heap_trim_s: float = 0.0,
) -> None:
    """Serve ``server`` (and ``video``, ``jobs``, the links) until a signal or its end.

    stdout (stderr with ``--stdio``) gets a ``listening on URL`` line a listener,
    then ``video on URL``. With ``heap_trim_s``, the process's free heap is given
    back every that many seconds (``--heap-trim``:
    ``rwt_transports.process.allocator.keep_trimmed``).

    Raises:
        ListenError: a listener, or the video server, could not bind its address.
        BagError: the bag to play cannot be read.
    """
    out = sys.stderr if server.config.stdio else sys.stdout  # stdout is the stdio session
    async with (
        linked(server.graph, zenoh),
        linked_ros2(server.graph, ros2),
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(_stop_on_signal, server, tg.cancel_scope)
        if heap_trim_s > 0:
            tg.start_soon(keep_trimmed, heap_trim_s)
        if jobs is not None:  # a bag to play is checked before anything is served
            await tg.start(jobs.run)
        video_url = None if video is None else await _start_video(tg, server, video)
        await tg.start(_serve, server, tg, out)
        ws_url = server.urls.get("websocket")
        if video is not None and video.console is not None and ws_url:
            video.console.websocket_port = _port(ws_url)
        if video_url:
            print(f"video on {video_url}", file=out, flush=True)


async def _start_video(tg: TaskGroup, server: GraphServer, video: VideoConfig) -> str:
    """Start the HTTP video server; the console on the WebSocket port links to it."""
    # the video server (Pillow, numpy) loads only with --video (B11: base memory)
    from rwt_video import serve_video  # noqa: PLC0415

    try:
        video_url: str = await tg.start(serve_video, server.graph, video)
    except OSError as exc:
        raise ListenError("HTTP video", video.host, video.port, exc) from exc
    site = server.console
    if site is not None:  # the console on either port shows the streams
        site.video_port = _port(video_url)
    if video.console is not None:
        video.console.video_port = _port(video_url)
    return video_url


async def _serve(
    server: GraphServer, tg: TaskGroup, out: TextIO, *, task_status: TaskStatus[str]
) -> None:
    """Run the listeners; a graceful stop ends the video server and the links too."""

    def announce(url: str) -> None:
        print(f"listening on {url}", file=out, flush=True)

    await server.serve(on_listening=announce, task_status=task_status)
    tg.cancel_scope.cancel()


def _port(url: str) -> int | None:
    return urlsplit(url).port


async def _stop_on_signal(server: GraphServer, scope: anyio.CancelScope) -> None:
    """First SIGINT/SIGTERM: stop gracefully; a second one: stop at once."""
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for signum in signals:
            logging.getLogger("rwt.server").info(
                "event=signal name=%s", signal.Signals(signum).name
            )
            if server.stop_requested:
                scope.cancel()
                return
            server.stop()
