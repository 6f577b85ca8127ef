"""An embedded rwt server with WebRTC and a 320x240 camera at 15 Hz, for the WHEP player test.

Usage: python camera_robot.py. Prints ``listening on ws://HOST:PORT`` (a free port),
then serves until SIGINT/SIGTERM, logging to stderr. ``/camera/image`` is rgb8, the
left half red, the right half blue, with a white bar moving across so frames differ.
"""

from __future__ import annotations

import logging
import signal
import sys

import anyio
import anyio.abc
import numpy as np

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_graph.media import array_to_image
from rwt_transports.webrtc.signalling import WebRtcOptions

RED, BLUE = (220, 30, 30), (30, 30, 220)


async def camera(graph: Graph) -> None:
    """/camera/image at 15 Hz."""
    publisher = graph.create_publisher("/camera/image", "sensor_msgs/msg/Image")
    for tick in range(1_000_000_000):
        frame = np.zeros((240, 320, 3), dtype=np.uint8)
        frame[:, :160], frame[:, 160:] = RED, BLUE
        frame[:, (tick * 4) % 320 : (tick * 4) % 320 + 8] = 255
        publisher.publish(array_to_image(frame, "rgb8"))
        await anyio.sleep(1 / 15)


async def main() -> None:
    logging.basicConfig(level=logging.INFO)  # the connection log, to stderr
    graph = Graph()
    stack = sys.argv[1] if len(sys.argv) > 1 else "auto"  # --webrtc-stack's choices
    config = ServerConfig(host="127.0.0.1", port=0, webrtc=WebRtcOptions(stack=stack))
    server = RosbridgeServer(graph, config)
    async with anyio.create_task_group() as tg:
        tg.start_soon(camera, graph)

        async def serve(*, task_status: anyio.abc.TaskStatus[str]) -> None:
            on_listening = lambda url: print("listening on", url, flush=True)  # noqa: E731
            await server.serve(task_status=task_status, on_listening=on_listening)
            tg.cancel_scope.cancel()  # stopped gracefully: the camera goes too

        await tg.start(serve)
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for _ in signals:
                server.stop()
                return


if __name__ == "__main__":
    anyio.run(main)
