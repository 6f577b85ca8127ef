"""The robot ``python -m benchmarks console`` looks at: an embedded rwt server with its
console and video server, a camera and many idle topics.

Usage: ``python -m benchmarks.console_robot [--topics 500] [--rate 30]``. Prints
``listening on ws://HOST:PORT`` and ``video on http://HOST:PORT``, then serves until
SIGINT/SIGTERM. The camera is ``/bench/camera``, 640x480 ``rgb8`` at ``--rate`` Hz
(the paper's synthetic camera: texture, motion, noise; 30 frames played in a loop);
the idle topics are ``/bench/idle_NNN`` (``std_msgs/String``, never published).
"""

from __future__ import annotations

import argparse
import signal
import time

import anyio
import anyio.abc

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_console import ConsoleSite
from rwt_graph.media import array_to_image
from rwt_transports.websocket import WebSocketOptions
from rwt_video import VideoConfig, serve_video

from .paper.video import camera_frames

CAMERA = "/bench/camera"
IDLE = "/bench/idle_{:03d}"


async def camera(graph: Graph, rate_hz: float) -> None:
    """Publish ``CAMERA`` at ``rate_hz``, on a fixed schedule (a late frame is not made up)."""
    frames = [array_to_image(frame, "rgb8") for frame in camera_frames(30)]
    publisher = graph.create_publisher(CAMERA, "sensor_msgs/msg/Image")
    period = 1.0 / rate_hz
    due = time.monotonic()
    index = 0
    while True:
        publisher.publish(frames[index % len(frames)])
        index += 1
        due = max(due + period, time.monotonic())
        await anyio.sleep(max(0.0, due - time.monotonic()))


async def main(topics: int, rate_hz: float) -> None:
    """Serve until a signal; see the module's docstring."""
    graph = Graph()
    for index in range(topics):
        graph.create_publisher(IDLE.format(index), "std_msgs/msg/String")
    console = ConsoleSite()
    config = ServerConfig(host="127.0.0.1", port=0, websocket=WebSocketOptions(console=console))
    server = RosbridgeServer(graph, config)
    async with anyio.create_task_group() as tg:
        video = await tg.start(serve_video, graph, VideoConfig(port=0))
        console.video_port = int(video.rsplit(":", 1)[1])
        tg.start_soon(camera, graph, rate_hz)

        async def serve(*, task_status: anyio.abc.TaskStatus[str]) -> None:
            await server.serve(task_status=task_status)
            tg.cancel_scope.cancel()

        url = await tg.start(serve)
        print(f"listening on {url}\nvideo on {video}", flush=True)
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for _ in signals:
                server.stop()
                return


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--topics", type=int, default=500, help="idle topics to list")
    parser.add_argument("--rate", type=float, default=30.0, help="camera frames per second")
    args = parser.parse_args()
    anyio.run(main, args.topics, args.rate)
