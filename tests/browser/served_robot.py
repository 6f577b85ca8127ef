"""An embedded rwt server with the console, rosauth, parameters and an action, for the browser.

Usage: python served_robot.py SECRET. Prints ``listening on ws://HOST:PORT`` (a free
port), then serves until SIGINT/SIGTERM. The same shape as examples/robot.py, plus
``ConsoleSite`` (what ``rwt serve`` turns on by default) and ``rosauth_authenticator``.
"""

from __future__ import annotations

import signal
import sys
from typing import Any

import anyio

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_console import ConsoleSite
from rwt_transports.server import rosauth_authenticator
from rwt_transports.websocket import WebSocketOptions


async def fibonacci(goal: dict[str, Any], context: Any) -> dict[str, Any]:
    sequence = [0, 1]
    for _ in range(1, goal["order"]):
        sequence.append(sequence[-1] + sequence[-2])
        context.publish_feedback({"sequence": sequence})
        await anyio.sleep(0.05)
    return {"sequence": sequence}


async def main(secret: str) -> None:
    graph = Graph()
    graph.params.declare("/robot", {"max_speed": 1.5, "name": "console-bot"})
    graph.create_action_server("/fibonacci", "example_interfaces/action/Fibonacci", fibonacci)
    console = ConsoleSite(auth=True)
    config = ServerConfig(host="127.0.0.1", port=0, websocket=WebSocketOptions(console=console))
    server = RosbridgeServer(
        graph, config, authenticator=rosauth_authenticator(secret, graph.clock)
    )
    async with anyio.create_task_group() as tg:
        await tg.start(
            lambda *, task_status: server.serve(
                task_status=task_status,
                on_listening=lambda url: print("listening on", url, flush=True),
            )
        )
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for _ in signals:
                server.stop()
                return


if __name__ == "__main__":
    anyio.run(main, sys.argv[1])
