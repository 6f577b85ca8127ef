"""``python -m benchmarks ros2 --graph``: how soon rosapi lists a new ROS 2 node's topics.

This process runs a graph with rosapi and its ROS 2 link (``open_ros2_link``, as
``rwt serve --ros2`` does), and two watchers on one clock (``time.monotonic``, the
same in every process here):

- the middleware's report: a thread reading the link's own rclpy node's graph
  (``get_topic_names_and_types``, what ``ros2 topic list`` reads) every
  ``MW_POLL_S``: the moment rclpy could first tell the link;
- rosapi: a task on the event loop calling ``/rosapi/topics`` every
  ``ROSAPI_POLL_S`` (the call a rosbridge client makes, without the socket).

Each round starts a real rclpy node in its own process with N publishers
(``std_msgs/msg/String``) on fresh names, and records, from the moment the node
said it had made them, when each watcher first listed one of them and when it
listed all of them. The lag is rosapi's time minus the middleware's: what rwt
adds to discovery (its graph reads, its sweep), which its design puts under
``GRAPH_POLL_S`` plus a sweep; discovery itself (the middleware's columns) varies
from round to round. Rounds of 1 and N topics alternate. The table gives each
round and the median and the largest lag per N; the load (``os.getloadavg``) is
printed with it. Every process of a run uses the Fast DDS setup ``--fastdds``
names (ros2_bridge.py's ``FASTDDS``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import anyio

from .ros2_bridge import FASTDDS, rclpy_available, ros_env

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable

__all__ = ["Round", "main", "run", "table"]

MW_POLL_S = 0.002
"""How often the watcher thread reads the link's node's topic names (s)."""
ROSAPI_POLL_S = 0.005
"""How often ``/rosapi/topics`` is called (s), besides each call's own time."""
ROUND_LIMIT_S = 30.0
"""A round that has not listed every topic on both sides by then fails."""
DOMAIN = 120
"""The run's ``ROS_DOMAIN_ID`` (``--domain``): clear of the tests' (100-119, from 140)."""

PEER = """
import sys, time
import rclpy
from std_msgs.msg import String
count, prefix = int(sys.argv[1]), sys.argv[2]
rclpy.init()
node = rclpy.create_node("graph_bench_" + prefix.strip("/"))
pubs = [node.create_publisher(String, f"{prefix}/t{n:03}", 10) for n in range(count)]
print(time.monotonic(), flush=True)
sys.stdin.readline()
"""


@dataclass
class Round:
    """One round's times, in seconds after the node said its publishers existed."""

    topics: int
    mw_first: float
    mw_all: float
    rosapi_first: float
    rosapi_all: float

    @property
    def lag(self) -> float:
        """rosapi's full listing minus the middleware's (s)."""
        return self.rosapi_all - self.mw_all


class _Seen:
    """When one of ``wanted`` was first listed, and all of them (monotonic s; 0: not yet)."""

    def __init__(self, wanted: set[str]) -> None:
        self.wanted = wanted
        self.first = self.all = 0.0

    def saw(self, names: set[str]) -> bool:
        """Note what ``names`` holds of ``wanted``; True once all of it was listed."""
        seen, now = self.wanted & names, time.monotonic()
        self.first = self.first or (now if seen else 0.0)
        self.all = now if seen == self.wanted else 0.0
        return bool(self.all)


def _watch_middleware(node: Any, seen: _Seen, deadline: float) -> None:
    while time.monotonic() < deadline:
        if seen.saw({name for name, _ in node.get_topic_names_and_types()}):
            return
        time.sleep(MW_POLL_S)


async def _watch_rosapi(ask: Callable[[], Awaitable[set[str]]], seen: _Seen, end: float) -> None:
    while time.monotonic() < end:
        if seen.saw(await ask()):
            return
        await anyio.sleep(ROSAPI_POLL_S)


async def _one_round(
    count: int, prefix: str, node: Any, ask: Callable[[], Awaitable[set[str]]], env: dict
) -> Round:
    wanted = {f"{prefix}/t{n:03}" for n in range(count)}
    mw, rosapi = _Seen(wanted), _Seen(wanted)
    async with await anyio.open_process(
        [sys.executable, "-c", PEER, str(count), prefix],
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
    ) as peer:
        assert peer.stdout is not None and peer.stdin is not None
        with anyio.fail_after(ROUND_LIMIT_S):
            start = float((await peer.stdout.receive()).decode())
        deadline = start + ROUND_LIMIT_S
        thread = threading.Thread(target=_watch_middleware, args=(node, mw, deadline))
        thread.start()
        await _watch_rosapi(ask, rosapi, deadline)
        await anyio.to_thread.run_sync(thread.join)
        await peer.stdin.send(b"done\n")
    if not (mw.all and rosapi.all):
        raise RuntimeError(f"{prefix}: not all {count} topics listed within {ROUND_LIMIT_S} s")
    return Round(count, mw.first - start, mw.all - start, rosapi.first - start, rosapi.all - start)


async def _rounds(rounds: int, topics: int, env: dict[str, str]) -> list[Round]:
    from rwt_graph.async_calls import call_service  # noqa: PLC0415
    from rwt_graph.graph import Graph  # noqa: PLC0415
    from rwt_graph.rosapi import install_rosapi  # noqa: PLC0415
    from rwt_ros2 import Ros2Options, open_ros2_link  # noqa: PLC0415

    graph = Graph()
    install_rosapi(graph)

    async def ask() -> set[str]:
        answer = await call_service(graph, "/rosapi/topics", {}, timeout_s=10)
        return set(answer["topics"])  # type: ignore[arg-type]

    results = []
    async with open_ros2_link(graph, Ros2Options(node_name="graph_bench")) as link:
        node = link.ros.node
        await _one_round(1, "/gb_warm", node, ask, env)  # not counted: the first discovery
        for r in range(rounds):
            for count in (1, topics):
                results.append(await _one_round(count, f"/gb{r}_{count}", node, ask, env))
    return results


def run(rounds: int, topics: int, domain: int, fastdds: str = "loopback") -> list[Round]:
    """``rounds`` rounds of 1 and ``topics`` topics each, alternating, after one not
    counted; this process and the nodes in ``ros_env(domain, fastdds)``.

    Raises:
        RuntimeError: rclpy is missing, a node did not start, or a round did not list
            every topic within ``ROUND_LIMIT_S``.
    """
    if not rclpy_available():
        raise RuntimeError('rclpy is not importable: pip install "rwt-rosbridge[ros2]"')
    env = {**os.environ, **ros_env(domain, fastdds)}
    saved = dict(os.environ)
    os.environ.update(env)  # the link's rclpy reads it
    try:
        return anyio.run(_rounds, rounds, topics, env)
    finally:
        os.environ.clear()
        os.environ.update(saved)


def table(results: list[Round]) -> str:
    """Each round (ms after the node was up), then the median and largest lag per N."""
    lines = [
        "| topics | middleware: first | all | rosapi: first | all | lag (ms) |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        times = (r.mw_first, r.mw_all, r.rosapi_first, r.rosapi_all, r.lag)
        lines.append(f"| {r.topics} | " + " | ".join(f"{1000 * t:.0f}" for t in times) + " |")
    for count in sorted({r.topics for r in results}):
        lags = [r.lag for r in results if r.topics == count]
        lines.append(
            f"\n{count} topics: lag median {1000 * statistics.median(lags):.0f} ms, "
            f"largest {1000 * max(lags):.0f} ms ({len(lags)} rounds)"
        )
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """``python -m benchmarks ros2 --graph [--rounds R] [--topics N] [--domain D] [--fastdds]``."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks ros2 --graph", description=__doc__)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--topics", type=int, default=200)
    parser.add_argument("--domain", type=int, default=DOMAIN)
    parser.add_argument("--fastdds", choices=sorted(FASTDDS), default="loopback")
    args = parser.parse_args(argv)
    load = os.getloadavg()
    results = run(args.rounds, args.topics, args.domain, args.fastdds)
    print(table(results))
    print(f"load average before the run: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    return 0
