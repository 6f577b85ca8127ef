"""The bare relay every scenario is measured against (docs/benchmarks.md).

A minimal ``websockets`` server: each incoming message is forwarded with
``broadcast()`` to every other connection that connected on ``/sub/<group>``
where ``<group>`` is the group of the sender's path (``/pub/<group>`` or
``/sub/<group>``; ``/`` and ``/sub`` are the group ``""``), without parsing.
The group stands for a topic: routing by path costs nothing per message.
Keep-alive pings and permessage-deflate are off, so its frames are
the plain frames a subscriber of ``rwt serve`` gets. On connect it sends one
text frame ``ready`` once the connection is registered, which the load
generator uses as its start barrier (rwt's barrier is a service reply).

Run: ``python -m benchmarks.relay --port 0`` (prints ``listening on ws://...``).
"""

from __future__ import annotations

import argparse
import asyncio
import signal

from websockets.asyncio.server import ServerConnection, broadcast, serve
from websockets.exceptions import ConnectionClosed

_groups: dict[str, set[ServerConnection]] = {}


async def _handler(websocket: ServerConnection) -> None:
    path = websocket.request.path if websocket.request is not None else "/"
    role, _, group = path.strip("/").partition("/")
    subscribers = _groups.setdefault(group, set())
    is_subscriber = role == "sub"
    if is_subscriber:
        subscribers.add(websocket)
    try:
        await websocket.send("ready")
        async for message in websocket:
            broadcast(subscribers - {websocket} if is_subscriber else subscribers, message)
    except ConnectionClosed:
        pass  # the load generator closes its sockets without a close frame
    finally:
        subscribers.discard(websocket)


async def _main(port: int, use_uvloop: bool) -> None:
    stop = asyncio.get_running_loop().create_future()
    for signum in (signal.SIGINT, signal.SIGTERM):
        asyncio.get_running_loop().add_signal_handler(signum, stop.set_result, None)
    async with serve(
        _handler,
        "127.0.0.1",
        port,
        compression=None,
        ping_interval=None,
        max_size=None,
        max_queue=None,
    ) as server:
        bound = next(iter(server.sockets)).getsockname()[1]
        print(f"listening on ws://127.0.0.1:{bound}", flush=True)
        await stop


def main() -> None:
    """Parse ``--port`` and ``--uvloop`` and serve until SIGINT/SIGTERM."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--uvloop", action="store_true")
    args = parser.parse_args()
    if args.uvloop:
        import uvloop  # noqa: PLC0415  (optional dependency)

        uvloop.run(_main(args.port, True))
    else:
        asyncio.run(_main(args.port, False))


if __name__ == "__main__":
    main()
