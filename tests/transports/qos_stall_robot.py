"""A robot for tests/transports/test_qos_lifespan_stall.py: a 1 kHz topic served on WS, TCP, WebRTC.

Run as a script (its own process, so that a test may stall its WebRTC peer's whole
event loop): it prints one ``listening on URL`` line per listener, then publishes
``/stream`` (``std_msgs/msg/String``) every millisecond until killed. Each message's
``data`` is ``SEQ|STAMP|`` (the sequence number from 0, the graph's wall-clock time of
the publish in seconds) padded with ``x`` to ``MESSAGE_CHARS`` characters, so a client
tells each message's age from its own clock, on the same machine.
"""

from __future__ import annotations

import sys
import time

import anyio

import rwt
from rwt.server import WebRtcOptions

TOPIC = "/stream"
MESSAGE_CHARS = 8000
"""Characters of a message's ``data``: a 5 s stall at 1 kHz is 40 MB, far more than any
socket buffer holds (docs/limits.md, "Lifespan across a stalled link")."""
PERIOD_S = 0.001


async def _publish(graph: rwt.Graph) -> None:
    publisher = graph.create_publisher(TOPIC, "std_msgs/msg/String")
    seq = 0
    while True:
        head = f"{seq}|{time.time():.6f}|"
        publisher.publish({"data": head.ljust(MESSAGE_CHARS, "x")})
        seq += 1
        await anyio.sleep(PERIOD_S)


async def main() -> None:
    graph = rwt.Graph()
    config = rwt.ServerConfig(
        host="127.0.0.1", port=0, tcp_port=0, webrtc=WebRtcOptions(stack="aiortc")
    )
    server = rwt.GraphServer(graph, config)
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        for url in server.urls.values():
            print(f"listening on {url}", flush=True)
        tg.start_soon(_publish, graph)


if __name__ == "__main__":
    try:
        anyio.run(main)
    except KeyboardInterrupt:
        sys.exit(0)
