"""An embedded rwt server with a map, TF and named nodes, for the console's Node graph and Map.

Usage: python mapped_robot.py. Prints ``listening on ws://HOST:PORT`` (a free port),
then serves until SIGINT/SIGTERM. In-process nodes, named as a robot's would be:

- /map_server latches the OccupancyGrid of ``cell_value`` on /map;
- /static_tf latches map -> odom and base_link -> laser on /tf_static;
- /odometry publishes odom -> base_link on /tf at 10 Hz;
- /amcl latches ``ROBOT_POSE`` (a PoseStamped in odom) on /robot_pose;
- /talker publishes /chatter (and /rosout, a debug topic) to /listener;
- 40 /sensor_NN nodes publish /sensors/sNN to /fusion, which publishes /cmd_vel to /base,
  which publishes /odom to /fusion (a cycle).
"""

from __future__ import annotations

import math
import signal
from typing import Any

import anyio

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_console import ConsoleSite
from rwt_transports.websocket import WebSocketOptions

WIDTH, HEIGHT, RESOLUTION = 40, 30, 0.1
ORIGIN = (-1.0, -1.0)
SENSORS = 40
# the map's known cells: (column, row) -> value; every other cell is free (0)
UNKNOWN_CELL, OCCUPIED_CELL, HALF_CELL, FREE_CELL = (2, 15), (20, 1), (32, 12), (35, 25)
# map -> odom and odom -> base_link: base_link is at (1.5, 1.0) in map, heading +y
MAP_TO_ODOM = (1.0, 0.5, 0.0)
ODOM_TO_BASE = (0.5, 0.5, math.pi / 2)
# /robot_pose, in odom: (1.5, 0.0) in map, heading +x
ROBOT_POSE = (0.5, -0.5, 0.0)


def cell_value(column: int, row: int) -> int:
    """Unknown (-1) in the first 5 columns, occupied (100) in the first 3 rows, 50 in a
    block around HALF_CELL, free (0) elsewhere."""
    if column < 5:
        return -1
    if row < 3:
        return 100
    if abs(column - HALF_CELL[0]) <= 2 and abs(row - HALF_CELL[1]) <= 2:
        return 50
    return 0


def occupancy_grid() -> dict[str, Any]:
    """The map: WIDTH x HEIGHT cells of RESOLUTION m, row 0 at ORIGIN (row-major, y up)."""
    return {
        "header": {"frame_id": "map"},
        "info": {
            "resolution": RESOLUTION,
            "width": WIDTH,
            "height": HEIGHT,
            "origin": {"position": {"x": ORIGIN[0], "y": ORIGIN[1], "z": 0.0}},
        },
        "data": [cell_value(c, r) for r in range(HEIGHT) for c in range(WIDTH)],
    }


def transform(parent: str, child: str, pose: tuple[float, float, float]) -> dict[str, Any]:
    x, y, yaw = pose
    return {
        "header": {"frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": {"x": x, "y": y, "z": 0.0},
            "rotation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)},
        },
    }


async def main() -> None:
    graph = Graph()
    graph.create_publisher(
        "/map", "nav_msgs/msg/OccupancyGrid", latch=True, node="/map_server"
    ).publish(occupancy_grid())
    static = graph.create_publisher(
        "/tf_static", "tf2_msgs/msg/TFMessage", latch=True, node="/static_tf"
    )
    laser = (0.2, 0.0, 0.0)
    static.publish(
        {
            "transforms": [
                transform("map", "odom", MAP_TO_ODOM),
                transform("base_link", "laser", laser),
            ]
        }
    )
    x, y, yaw = ROBOT_POSE
    graph.create_publisher(
        "/robot_pose", "geometry_msgs/msg/PoseStamped", latch=True, node="/amcl"
    ).publish(
        {
            "header": {"frame_id": "odom"},
            "pose": {
                "position": {"x": x, "y": y, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)},
            },
        }
    )
    tf = graph.create_publisher("/tf", "tf2_msgs/msg/TFMessage", node="/odometry")
    chatter = graph.create_publisher("/chatter", "std_msgs/msg/String", node="/talker")
    graph.create_publisher("/rosout", "rcl_interfaces/msg/Log", node="/talker")
    graph.create_subscription("/chatter", lambda msg: None, "std_msgs/msg/String", node="/listener")
    for i in range(SENSORS):
        topic = f"/sensors/s{i:02d}"
        graph.create_publisher(topic, "std_msgs/msg/Float32", node=f"/sensor_{i:02d}")
        graph.create_subscription(topic, lambda msg: None, "std_msgs/msg/Float32", node="/fusion")
    graph.create_publisher("/cmd_vel", "geometry_msgs/msg/Twist", node="/fusion")
    graph.create_subscription("/cmd_vel", lambda msg: None, "geometry_msgs/msg/Twist", node="/base")
    graph.create_publisher("/odom", "nav_msgs/msg/Odometry", node="/base")
    graph.create_subscription("/odom", lambda msg: None, "nav_msgs/msg/Odometry", node="/fusion")
    console = ConsoleSite()
    config = ServerConfig(host="127.0.0.1", port=0, websocket=WebSocketOptions(console=console))
    server = RosbridgeServer(graph, config)

    async def publish() -> None:
        count = 0
        while True:
            count += 1
            tf.publish({"transforms": [transform("odom", "base_link", ODOM_TO_BASE)]})
            chatter.publish({"data": f"hello {count}"})
            await anyio.sleep(0.1)

    async with anyio.create_task_group() as tg:
        await tg.start(
            lambda *, task_status: server.serve(
                task_status=task_status,
                on_listening=lambda url: print("listening on", url, flush=True),
            )
        )
        tg.start_soon(publish)
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for _ in signals:
                server.stop()
                tg.cancel_scope.cancel()
                return


if __name__ == "__main__":
    anyio.run(main)
