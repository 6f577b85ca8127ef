"""A robot publishing TF from Python; web clients get transforms via the built-in republisher.

Usage: python examples/tf_robot.py [PORT] [ros2|ros1]

base_link -> arm slides back and forth along x by 1 cm every 50 ms, arm -> wrist
turns 0.02 rad every 50 ms, base_link -> camera is static. roslibjs ``TFClient``
or ``ROS2TFClient`` and roslibpy ``TFClient`` subscribe to these frames through
``/tf2_web_republisher`` and ``/republish_tfs`` and get them only when they move
beyond their thresholds.
"""

import itertools
import math
import sys
from contextlib import suppress

import anyio

from rwt import Graph, ListenError, RosbridgeServer, ServerConfig
from rwt.types import Dialect, TypeRegistry

port = int(sys.argv[1]) if sys.argv[1:] else 9090
graph = Graph(TypeRegistry(Dialect(sys.argv[2] if sys.argv[2:] else "ros2")))
tf = graph.create_publisher("/tf", "tf2_msgs/msg/TFMessage")
tf_static = graph.create_publisher("/tf_static", "tf2_msgs/msg/TFMessage", latch=True)


def link(parent: str, child: str, x: float = 0.0, yaw: float = 0.0) -> dict:
    """``child`` at ``x`` metres along ``parent``'s x axis, turned ``yaw`` radians (stamp: now)."""
    rotation = {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}
    return {
        "header": {"frame_id": parent},
        "child_frame_id": child,
        "transform": {"translation": {"x": x}, "rotation": rotation},
    }


async def move() -> None:
    tf_static.publish({"transforms": [link("base_link", "camera", 0.2)]})
    for step in itertools.count():
        x = 0.01 * abs(step % 100 - 50)  # 0.5 m and back
        tf.publish(
            {"transforms": [link("base_link", "arm", x), link("arm", "wrist", 0.1, step * 0.02)]}
        )
        await anyio.sleep(0.05)


async def main() -> str | None:
    """Serve and move until Ctrl-C; if the port is taken, return the error's one line."""
    server = RosbridgeServer(graph, ServerConfig(port=port))
    async with anyio.create_task_group() as tg:
        tg.start_soon(move)
        try:
            url = await tg.start(server.serve)
        except ListenError as exc:  # cannot listen for WebSocket on ...: address already in use
            tg.cancel_scope.cancel()
            return str(exc)
        print("listening on", url, flush=True)
    return None


with suppress(KeyboardInterrupt):  # Ctrl-C: stop without a traceback
    sys.exit(anyio.run(main))  # the error's line on stderr and exit code 1, or 0
