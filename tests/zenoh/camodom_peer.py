"""A linked graph in its own process publishing a camera and odometry on Zenoh.

Usage: ``python -m tests.zenoh.camodom_peer ENDPOINT`` (from the repository root):
connects to ``ENDPOINT`` (loopback, multicast off), prints ``ready`` once
linked, then publishes ``/cam`` (``sensor_msgs/msg/Image``, mono8 320x320: 100
KB) every 10 ms and ``/odom`` (``std_msgs/msg/String``, a count) every 20 ms,
for at most 60 s. A peer server with a camera and a robot base, as the link sees it.
"""

from __future__ import annotations

import sys
from typing import Any

import anyio

from rwt_graph.graph import Graph
from rwt_zenoh.link import open_zenoh_link

from .support import peer

LIFETIME_S = 60.0


async def paced(period_s: float, publish: Any) -> None:
    """Call ``publish(n)`` every ``period_s`` on a fixed schedule (n counts from 0)."""
    next_at = anyio.current_time()
    count = 0
    while True:
        publish(count)
        count += 1
        next_at += period_s
        await anyio.sleep(max(0.0, next_at - anyio.current_time()))


async def main(endpoint: str) -> None:
    graph = Graph()
    async with open_zenoh_link(graph, peer(connect=(endpoint,))):
        cam = graph.create_publisher("/cam", "sensor_msgs/msg/Image", node="/camera")
        odom = graph.create_publisher("/odom", "std_msgs/msg/String", node="/base")
        image = {
            "height": 320,
            "width": 320,
            "encoding": "mono8",
            "step": 320,
            "data": bytes(320 * 320),
        }
        print("ready", flush=True)
        with anyio.move_on_after(LIFETIME_S):
            async with anyio.create_task_group() as tg:
                tg.start_soon(paced, 0.01, lambda _: cam.publish(image))
                tg.start_soon(paced, 0.02, lambda n: odom.publish({"data": str(n)}))


if __name__ == "__main__":
    anyio.run(main, sys.argv[1])
