"""An embedded rwt server with the console, typed parameters and two publishers, for the browser.

Usage: python panels_robot.py. Prints ``listening on ws://HOST:PORT`` (a free port),
then serves until SIGINT/SIGTERM. The parameters of ``/robot`` cover every input the
Parameters tab has (a double, an int, a bool, a string, an array) and a read-only one
the server refuses to set; ``/odom`` (with a header) and ``/temperature`` publish at
20 Hz for the Plot tab.
"""

from __future__ import annotations

import math
import signal

import anyio

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_console import ConsoleSite
from rwt_transports.websocket import WebSocketOptions

PARAMS = {
    "max_speed": 1.5,
    "retries": 3,
    "verbose": False,
    "name": "console-bot",
    "gains": [1.0, 2.0],
}
PERIOD_S = 0.05


async def publish(graph: Graph) -> None:
    odom = graph.create_publisher("/odom", "nav_msgs/msg/Odometry")
    temperature = graph.create_publisher("/temperature", "std_msgs/msg/Float64")
    t = 0.0
    while True:
        stamp = {"sec": int(t), "nanosec": int((t % 1) * 1e9)}
        position = {"x": math.cos(t), "y": math.sin(t), "z": 0.0}
        odom.publish(
            {
                "header": {"stamp": stamp, "frame_id": "odom"},
                "pose": {"pose": {"position": position}},
            }
        )
        temperature.publish({"data": 20.0 + t})
        await anyio.sleep(PERIOD_S)
        t += PERIOD_S


async def main() -> None:
    graph = Graph()
    graph.params.declare("/robot", PARAMS)
    graph.params.declare("/robot", {"serial": "X-1"}, read_only=True)
    config = ServerConfig(
        host="127.0.0.1", port=0, websocket=WebSocketOptions(console=ConsoleSite())
    )
    server = RosbridgeServer(graph, config)
    async with anyio.create_task_group() as tg:
        tg.start_soon(publish, graph)
        await tg.start(
            lambda *, task_status: server.serve(
                task_status=task_status,
                on_listening=lambda url: print("listening on", url, flush=True),
            )
        )
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for _ in signals:
                server.stop()
                tg.cancel_scope.cancel()
                return


if __name__ == "__main__":
    anyio.run(main)
