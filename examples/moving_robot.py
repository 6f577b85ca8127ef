"""A robot that moves: /tf, /odom at 20 Hz, and latched /tf_static and /map (for recording)."""

import math
import sys
from contextlib import suppress

import anyio

from rwt import Graph, ListenError, RosbridgeServer, ServerConfig

graph = Graph()
tf = graph.create_publisher("/tf", "tf2_msgs/msg/TFMessage")
odom = graph.create_publisher("/odom", "nav_msgs/msg/Odometry")
static = graph.create_publisher("/tf_static", "tf2_msgs/msg/TFMessage", latch=True)
grid = graph.create_publisher("/map", "nav_msgs/msg/OccupancyGrid", latch=True)


def transform(parent: str, child: str, x: float, y: float, yaw: float) -> dict:
    rotation = {"z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}
    pose = {"translation": {"x": x, "y": y}, "rotation": rotation}
    return {"header": {"frame_id": parent}, "child_frame_id": child, "transform": pose}


async def drive() -> None:
    static.publish({"transforms": [transform("base_link", "laser", 0.2, 0.0, 0.0)]})
    cells = [100 if x in (0, 9) or y in (0, 9) else 0 for y in range(10) for x in range(10)]
    grid.publish(
        {
            "header": {"frame_id": "map"},
            "info": {"resolution": 0.5, "width": 10, "height": 10},
            "data": cells,
        }
    )
    t = 0.0
    while True:
        x, y, yaw = math.cos(t), math.sin(t), t + math.pi / 2  # a circle of 1 m, 1 rad/s
        tf.publish({"transforms": [transform("odom", "base_link", x, y, yaw)]})
        odom.publish(
            {
                "header": {"frame_id": "odom"},
                "child_frame_id": "base_link",
                "pose": {"pose": {"position": {"x": x, "y": y}}},
            }
        )
        await anyio.sleep(0.05)
        t += 0.05


async def main() -> str | None:
    """Serve and drive until Ctrl-C; if the port is taken, return the error's one line."""
    server = RosbridgeServer(graph, ServerConfig(port=int(sys.argv[1]) if sys.argv[1:] else 9090))
    async with anyio.create_task_group() as tg:
        tg.start_soon(drive)
        try:
            url = await tg.start(server.serve)
        except ListenError as exc:  # cannot listen for WebSocket on ...: address already in use
            tg.cancel_scope.cancel()
            return str(exc)
        print("listening on", url, flush=True)
    return None


with suppress(KeyboardInterrupt):  # Ctrl-C: stop without a traceback
    sys.exit(anyio.run(main))  # the error's line on stderr and exit code 1, or 0
