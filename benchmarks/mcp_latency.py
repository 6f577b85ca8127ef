"""B23: MCP tool-call latency, rwt's MCP server against ros-mcp on the same robot.

``python -m benchmarks.mcp_latency [--calls 30]``. One robot (an rwt server with
``--mcp`` in a process of its own: a latched ``/battery``, a ``/cmd`` subscriber,
a ``/lights`` service) and three MCP servers in front of it, each driven by the
official MCP Python client in this process:

- ``rwt serve --mcp``: Streamable HTTP at the robot's own ``/mcp``;
- ``rwt mcp URL``: stdio, one persistent rosbridge connection;

each of these two by a 2025-era client (the ``initialize`` handshake, a session:
2025-11-25) and by a 2026-07-28 one (the SDK's ``Client`` discovering the revision:
no handshake, ``_meta`` on every request), in the same run;

- ros-mcp 3.1.2: stdio, a rosbridge connection per tool call. It holds mcp below 2,
  so it runs from an environment of its own (docs/decisions.md D52): ``--ros-mcp-python``
  (or ``RWT_ROS_MCP_PYTHON``) names its Python.

Four comparable calls: list the topics, read one latched message, publish one
message, call a service. Each is timed from the client's ``call_tool`` to its
answer, ``--calls`` times after two warm-up rounds; the rounds are paced at
``PACE_S`` so that no call meets rwt's per-tool rate cap (docs/mcp.md). Prints a
table (p50 and p99 in ms) and writes ``benchmarks/results/mcp_latency.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import httpx2
from mcp import ClientSession, StdioServerParameters
from mcp.client.client import Client
from mcp.client.stdio import stdio_client
from mcp.client.streamable_http import streamable_http_client

RESULTS = Path(__file__).resolve().parent / "results"
SRC = Path(__file__).resolve().parents[1] / "src"
ENV = {**os.environ, "PYTHONPATH": str(SRC)}
PACE_S = 0.55
"""Seconds between two calls of one tool: under rwt's caps, 10 calls of a tool a second
(TOOL_CALLS_PER_S) and 2 listings a second (LISTING_CALLS_PER_S, which the listing of
the topics counts against)."""
GAP_S = 0.06
"""Seconds between two calls of a round: over ``1 / HOST_SESSIONS_PER_S`` (50 ms), the
pace of a host's 2026-07-28 requests (D55), so each call's time is its own and not its
wait for the host's turn."""

# each call as (rwt's tool, its arguments), (ros-mcp's tool, its arguments)
CALLS: dict[str, tuple[tuple[str, dict[str, Any]], tuple[str, dict[str, Any]]]] = {
    "list topics": (("list_topics", {}), ("get_topics", {})),
    "read a latched message": (
        ("echo", {"topic": "/battery", "type": "std_msgs/msg/String"}),
        ("subscribe_once", {"topic": "/battery", "msg_type": "std_msgs/msg/String"}),
    ),
    "publish one message": (
        ("publish", {"topic": "/cmd", "type": "std_msgs/msg/String", "msg": {"data": "go"}}),
        (
            "publish_once",
            {"topic": "/cmd", "msg_type": "std_msgs/msg/String", "msg": {"data": "go"}},
        ),
    ),
    "call a service": (
        (
            "call_service",
            {"service": "/lights", "type": "std_srvs/srv/SetBool", "args": {"data": True}},
        ),
        (
            "call_service",
            {
                "service_name": "/lights",
                "service_type": "std_srvs/srv/SetBool",
                "request": {"data": True},
            },
        ),
    ),
}

_ROBOT = """
import anyio
from rwt import Graph, RosbridgeServer, ServerConfig
from rwt.server import McpOptions

async def main() -> None:
    graph = Graph()
    graph.create_publisher("/battery", "std_msgs/msg/String", latch=True).publish({"data": "87%"})
    graph.create_subscription("/cmd", lambda msg: None, "std_msgs/msg/String")
    graph.create_service("/lights", "std_srvs/srv/SetBool", lambda req: {"success": req["data"]})
    server = RosbridgeServer(graph, ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions()))
    await server.serve(on_listening=lambda url: print(url, flush=True))

anyio.run(main)
"""


@asynccontextmanager
async def robot() -> AsyncIterator[str]:
    """The robot in a process of its own; its WebSocket URL."""
    process = subprocess.Popen(  # noqa: ASYNC220 (read once, at start)
        [sys.executable, "-c", _ROBOT], env=ENV, stdout=subprocess.PIPE, text=True
    )
    assert process.stdout is not None
    with process.stdout:
        try:
            yield process.stdout.readline().strip()
        finally:
            process.terminate()
            process.wait(10)


@asynccontextmanager
async def over_http(url: str) -> AsyncIterator[ClientSession]:
    endpoint = url.replace("ws://", "http://") + "/mcp"
    async with (
        httpx2.AsyncClient(timeout=httpx2.Timeout(30, read=300)) as http,
        streamable_http_client(endpoint, http_client=http) as (read, write),
        ClientSession(read, write) as session,
    ):
        await session.initialize()
        yield session


@asynccontextmanager
async def over_stdio(
    args: list[str], errlog: Path, python: str = sys.executable
) -> AsyncIterator[ClientSession]:
    params = StdioServerParameters(command=python, args=args, env=ENV)
    with errlog.open("w") as log:
        async with (
            stdio_client(params, errlog=log) as (read, write),
            ClientSession(read, write) as session,
        ):
            await session.initialize()
            yield session


@asynccontextmanager
async def modern(target: str | StdioServerParameters) -> AsyncIterator[ClientSession]:
    """A 2026-07-28 client (``server/discover``, then no handshake) on ``target``."""
    async with Client(target, mode="auto") as client:
        if client.protocol_version != "2026-07-28":
            raise RuntimeError(f"the client speaks {client.protocol_version}, not 2026-07-28")
        yield client.session


async def measure(
    session: ClientSession, ros_mcp: bool, calls: int, pace_s: float = PACE_S
) -> dict[str, list[float]]:
    """Milliseconds of each call, ``calls`` times each (after two warm-up rounds), a round
    every ``pace_s`` seconds at most."""
    times: dict[str, list[float]] = {name: [] for name in CALLS}
    for round_ in range(calls + 2):
        started = time.perf_counter()
        for name, pair in CALLS.items():
            tool, arguments = pair[ros_mcp]
            began = time.perf_counter()
            result = await session.call_tool(tool, arguments)
            elapsed_ms = (time.perf_counter() - began) * 1000
            text = json.dumps([block.model_dump() for block in result.content])
            if result.is_error or '"error"' in text:
                raise RuntimeError(f"{tool} failed: {text[:300]}")
            if round_ >= 2:
                times[name].append(elapsed_ms)
            await anyio.sleep(GAP_S)
        await anyio.sleep(max(0.0, pace_s - (time.perf_counter() - started)))
    return times


def _p(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


async def main(
    calls: int, ros_mcp_python: str, pace_s: float = PACE_S
) -> dict[str, dict[str, dict[str, float]]]:
    results: dict[str, dict[str, dict[str, float]]] = {}
    logs = Path(os.environ.get("TMPDIR", "/tmp"))
    async with robot() as url:
        stdio = StdioServerParameters(
            command=sys.executable, args=["-m", "rwt", "mcp", url], env=ENV
        )
        fronts: dict[str, tuple[Callable[[], AbstractAsyncContextManager[ClientSession]], bool]] = {
            "rwt serve --mcp (HTTP)": (lambda: over_http(url), False),
            "rwt serve --mcp (HTTP, 2026-07-28)": (
                lambda: modern(url.replace("ws://", "http://") + "/mcp"),
                False,
            ),
            "rwt mcp URL (stdio)": (
                lambda: over_stdio(["-m", "rwt", "mcp", url], logs / "b23-rwt-mcp.log"),
                False,
            ),
            "rwt mcp URL (stdio, 2026-07-28)": (lambda: modern(stdio), False),
            "ros-mcp 3.1.2 (stdio)": (
                lambda: over_stdio(
                    ["-m", "ros_mcp.main"], logs / "b23-ros-mcp.log", ros_mcp_python
                ),
                True,
            ),
        }
        for front, (opened, ros_mcp) in fronts.items():
            async with opened() as session:
                if ros_mcp:
                    port = int(url.rsplit(":", 1)[1])
                    await session.call_tool("connect_to_robot", {"ip": "127.0.0.1", "port": port})
                times = await measure(session, ros_mcp, calls, pace_s)
            results[front] = {
                name: {
                    "p50_ms": statistics.median(values),
                    "p99_ms": _p(values, 0.99),
                    "calls": len(values),
                }
                for name, values in times.items()
            }
            print(f"{front}: done", file=sys.stderr, flush=True)
    return results


def table(results: dict[str, dict[str, dict[str, float]]]) -> str:
    fronts = list(results)
    lines = [
        "| call | " + " | ".join(f"{front} p50 / p99 ms" for front in fronts) + " |",
        "|---|" + "---|" * len(fronts),
    ]
    for name in CALLS:
        cells = [
            f"{results[f][name]['p50_ms']:.1f} / {results[f][name]['p99_ms']:.1f}" for f in fronts
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=30, help="timed calls of each tool")
    parser.add_argument(
        "--ros-mcp-python",
        default=os.environ.get("RWT_ROS_MCP_PYTHON", sys.executable),
        help="a Python with ros-mcp 3.1.2 installed (its own environment)",
    )
    options = parser.parse_args()
    measured = anyio.run(main, options.calls, options.ros_mcp_python)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "mcp_latency.json").write_text(json.dumps(measured, indent=2) + "\n")
    print(table(measured))
