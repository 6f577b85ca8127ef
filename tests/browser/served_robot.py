"""An embedded rwt server with the console, rosauth, parameters, an action and a camera.

Usage: python served_robot.py SECRET. Prints ``listening on ws://HOST:PORT`` (a free
port), then serves until SIGINT/SIGTERM. The same shape as examples/robot.py, plus
``ConsoleSite`` (what ``rwt serve`` turns on by default), ``rosauth_authenticator``
and the video server opened by tokens (what ``--video --auth-secret-file`` does).
"""

from __future__ import annotations

import signal
import sys
from typing import Any

import anyio
import anyio.abc
import numpy as np

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_console import ConsoleSite
from rwt_graph.media import array_to_image
from rwt_transports.server import rosauth_authenticator
from rwt_transports.websocket import WebSocketOptions
from rwt_video import VideoConfig, VideoTokens, install_token_service, serve_video

RED, BLUE = (220, 30, 30), (30, 30, 220)


async def fibonacci(goal: dict[str, Any], context: Any) -> dict[str, Any]:
    sequence = [0, 1]
    for _ in range(1, goal["order"]):
        sequence.append(sequence[-1] + sequence[-2])
        context.publish_feedback({"sequence": sequence})
        await anyio.sleep(0.05)
    return {"sequence": sequence}


async def camera(graph: Graph) -> None:
    """/camera/image at 10 Hz: 64x48 rgb8, the left half red, the right half blue."""
    frame = np.zeros((48, 64, 3), dtype=np.uint8)
    frame[:, :32], frame[:, 32:] = RED, BLUE
    publisher = graph.create_publisher("/camera/image", "sensor_msgs/msg/Image")
    while True:
        publisher.publish(array_to_image(frame, "rgb8"))
        await anyio.sleep(0.1)


async def main(secret: str) -> None:
    graph = Graph()
    graph.params.declare("/robot", {"max_speed": 1.5, "name": "console-bot"})
    graph.create_action_server("/fibonacci", "example_interfaces/action/Fibonacci", fibonacci)
    console = ConsoleSite(auth=True, video_token=True)
    tokens = VideoTokens()
    install_token_service(graph, tokens)
    config = ServerConfig(host="127.0.0.1", port=0, websocket=WebSocketOptions(console=console))
    server = RosbridgeServer(
        graph, config, authenticator=rosauth_authenticator(secret, graph.clock)
    )
    async with anyio.create_task_group() as tg:
        video = await tg.start(serve_video, graph, VideoConfig(port=0, tokens=tokens))
        console.video_port = int(video.rsplit(":", 1)[1])
        tg.start_soon(camera, graph)

        async def serve(*, task_status: anyio.abc.TaskStatus[str]) -> None:
            on_listening = lambda url: print("listening on", url, flush=True)  # noqa: E731
            await server.serve(task_status=task_status, on_listening=on_listening)
            tg.cancel_scope.cancel()  # stopped gracefully: the camera and video go too

        await tg.start(serve)
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for _ in signals:
                server.stop()
                return


if __name__ == "__main__":
    anyio.run(main, sys.argv[1])
