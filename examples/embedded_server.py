"""Serve an in-process robot to rosbridge clients.

Python code publishes ``/counter`` (std_msgs/msg/Int32) once a second and prints
every ``/cmd_vel`` (geometry_msgs/msg/Twist) a client sends. Run it, then connect
roslibjs or roslibpy to the printed URL.

    python examples/embedded_server.py [--port 9090] [--count N]
"""

from __future__ import annotations

import argparse
import sys
from contextlib import suppress

import anyio

from rwt import Graph, ListenError, RosbridgeServer, ServerConfig


def on_cmd_vel(msg: dict[str, object]) -> None:
    """Print each velocity command."""
    print("cmd_vel:", msg["linear"], msg["angular"], flush=True)


async def main(port: int, count: int | None) -> str | None:
    """Run the server and the publishing loop; stop after ``count`` messages if given.

    If the port is taken, return the error's one line instead.
    """
    graph = Graph()
    graph.create_subscription("/cmd_vel", on_cmd_vel, "geometry_msgs/msg/Twist")
    counter = graph.create_publisher("/counter", "std_msgs/msg/Int32")
    server = RosbridgeServer(graph, ServerConfig(port=port))
    async with anyio.create_task_group() as tg:
        try:
            url = await tg.start(server.serve)
        except ListenError as exc:  # cannot listen for WebSocket on ...: address already in use
            return str(exc)
        print(f"listening on {url}", flush=True)
        n = 0
        while count is None or n < count:
            counter.publish({"data": n})
            n += 1
            await anyio.sleep(1.0)
        tg.cancel_scope.cancel()
    return None


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--port", type=int, default=9090)
    parser.add_argument("--count", type=int, default=None)
    args = parser.parse_args()
    with suppress(KeyboardInterrupt):  # Ctrl-C: stop without a traceback
        sys.exit(anyio.run(main, args.port, args.count))  # the error's line and exit code 1, or 0
