"""An in-process server with the HTTP API on a free port, and curl to ask it."""

from __future__ import annotations

import subprocess
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import replace

import anyio

from rwt_graph.graph import Graph
from rwt_transports.server import RosbridgeServer, ServerConfig


@asynccontextmanager
async def api_server(
    graph: Graph | None = None, config: ServerConfig | None = None, **server_kw: object
) -> AsyncIterator[tuple[RosbridgeServer, str]]:
    """``(server, "http://127.0.0.1:PORT")``: the WebSocket port, where the API is."""
    config = replace(config or ServerConfig(tf=False), port=0)
    server = RosbridgeServer(graph, config, **server_kw)  # type: ignore[arg-type]
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        url = server.urls["websocket"].replace("ws://", "http://").rstrip("/")
        try:
            yield server, url
        finally:
            server.stop()


async def curl(*args: str) -> tuple[int, str]:
    """curl's ``(status, body)`` for ``args`` (a URL and options), off the event loop."""

    def run() -> subprocess.CompletedProcess[str]:
        command = ["curl", "-sS", "--max-time", "20", "-w", "\n%{http_code}", *args]
        return subprocess.run(command, capture_output=True, text=True, check=False)

    done = await anyio.to_thread.run_sync(run)
    body, _, status = done.stdout.rpartition("\n")
    return int(status or 0), body
