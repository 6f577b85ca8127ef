"""In-process fan-out: one topic to N sessions of each protocol, this rwt against a base.

``python -m benchmarks.fanout_inproc [--base-src DIR] [--rounds 7] [--sessions 100]
[--publishes 200] [--protocols rosbridge foxglove] [--smoke]``

What a refactor of the connection runtime costs on the hot path, without sockets,
the event loop or a load generator between: a graph, ``sessions`` sessions of one
protocol (rosbridge's ``Session`` or Foxglove's ``FoxgloveSession``, driven sans-IO
as a transport would) subscribed to ``/fan`` (``std_msgs/msg/String``, 100 B), then
``publishes`` messages published in the process and every session's outbox drained
(``frames_to_send``). The figure is microseconds of the whole (publishes and drain)
per publish, the best of ``REPEATS`` in a worker process.

With ``--base-src`` (another checkout's ``src``, e.g. main's) each round runs a
worker on that rwt (kind ``base``) and one on this checkout's (kind ``rwt``), in
alternating order round by round, so both see the same machine; the table gives the
medians and the ratio rwt/base (below 1: this checkout is faster). A worker runs this
module with ``PYTHONPATH`` set to its ``src``; it uses only calls both sides have.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from rwt_foxglove import FoxgloveSession
from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.server.session import Session

if TYPE_CHECKING:  # (the worker on an older checkout has it elsewhere)
    from rwt_protocol.runtime.outbox import OutFrame

__all__ = ["fan_out", "main"]

ROOT = Path(__file__).resolve().parent.parent
TOPIC = "/fan"
STRING = "std_msgs/msg/String"
REPEATS = 5
PAYLOAD = "x" * 100
PROTOCOLS = ("rosbridge", "foxglove")


def fan_out(protocol: str, sessions: int, publishes: int) -> tuple[float, int]:
    """One measurement: ``sessions`` subscribers of ``protocol``, ``publishes`` messages.

    Returns:
        (microseconds per publish for the publishes and the drain, topic frames
        delivered in all; ``sessions * publishes`` when nothing was dropped).

    Raises:
        ValueError: an unknown ``protocol``.
    """
    graph = Graph(_types())
    publisher = graph.create_publisher(TOPIC, STRING)
    peers = [_subscriber(graph, protocol, n) for n in range(sessions)]
    for session in peers:  # what subscribing sent (advertise, serverInfo) is not timed
        session.frames_to_send(1 << 30)
    message = {"data": PAYLOAD}
    start = time.process_time()  # the CPU this process took: the other cores' load aside
    for _ in range(publishes):
        publisher.publish(message)
    delivered = 0
    for session in peers:
        delivered += len(session.frames_to_send(1 << 30))
    elapsed = time.process_time() - start
    for session in peers:
        session.close()
    return elapsed / publishes * 1e6, delivered


_TYPES: list[TypeRegistry] = []


def _types() -> TypeRegistry:
    """One registry for the worker: its codecs are made once, not in a timed run."""
    if not _TYPES:
        _TYPES.append(TypeRegistry(Dialect.ROS2))
    return _TYPES[0]


def _subscriber(graph: Graph, protocol: str, n: int) -> Session | FoxgloveSession:
    """A session of ``protocol`` subscribed to ``TOPIC`` (the calls main and this share)."""
    if protocol == "rosbridge":
        session = Session(graph.port, f"bench#{n}")
        subscribe = {"op": "subscribe", "topic": TOPIC, "type": STRING}
        session.receive_frame(json.dumps(subscribe), 0.0)
        return session
    if protocol == "foxglove":
        fox = FoxgloveSession(graph.port, f"foxglove:bench#{n}", session_id="s")
        channel = _channel_id(fox.frames_to_send(1 << 30))
        op: dict[str, object] = {
            "op": "subscribe",
            "subscriptions": [{"id": 1, "channelId": channel}],
        }
        fox.receive_frame(json.dumps(op).encode(), 0.0, binary=False)
        return fox
    raise ValueError(f"unknown protocol {protocol!r}")


def _channel_id(frames: Sequence[OutFrame]) -> int:
    """The id of ``TOPIC``'s channel in a Foxglove session's first frames."""
    for frame in frames:
        if frame.binary:
            continue
        op = json.loads(frame.data)
        if op.get("op") == "advertise":
            for channel in op["channels"]:
                if channel["topic"] == TOPIC:
                    return int(channel["id"])
    raise RuntimeError(f"{TOPIC} was not advertised")


def _worker(protocols: list[str], sessions: int, publishes: int, repeats: int) -> None:
    """Print one JSON line: per protocol the best µs per publish and the deliveries."""
    result: dict[str, dict[str, float]] = {}
    for protocol in protocols:
        fan_out(protocol, 2, 2)  # warm: the types and their codecs are built at first use
        runs = [fan_out(protocol, sessions, publishes) for _ in range(repeats)]
        result[protocol] = {
            "us_per_publish": min(us for us, _ in runs),
            "delivered": min(n for _, n in runs),
        }
    print(json.dumps(result))


def _run_worker(src: Path, args: argparse.Namespace) -> dict[str, dict[str, float]]:
    env = dict(os.environ, PYTHONPATH=str(src), RWT_LOG_LEVEL="ERROR")
    command = [sys.executable, "-m", "benchmarks.fanout_inproc", "--worker"]
    command += ["--sessions", str(args.sessions), "--publishes", str(args.publishes)]
    command += ["--repeats", str(args.repeats), "--protocols", *args.protocols]
    out = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def compare(args: argparse.Namespace) -> dict[str, dict[str, list[float]]]:
    """Run ``args.rounds`` rounds, alternating which kind goes first; the figures by kind."""
    kinds = {"rwt": ROOT / "src"}
    if args.base_src is not None:
        kinds["base"] = Path(args.base_src).resolve()
    found: dict[str, dict[str, list[float]]] = {k: {p: [] for p in args.protocols} for k in kinds}
    order = list(kinds)
    for round_ in range(args.rounds):
        for kind in order if round_ % 2 == 0 else order[::-1]:
            result = _run_worker(kinds[kind], args)
            expected = args.sessions * args.publishes
            for protocol, figures in result.items():
                if figures["delivered"] != expected:
                    raise RuntimeError(
                        f"{kind} {protocol}: {figures['delivered']} of {expected} delivered"
                    )
                found[kind][protocol].append(figures["us_per_publish"])
            print(f"round {round_ + 1} {kind}: {json.dumps(result)}", file=sys.stderr)
    return found


def _table(found: dict[str, dict[str, list[float]]]) -> str:
    lines = ["| protocol | rwt µs/publish | base µs/publish | rwt/base |", "|---|---|---|---|"]
    for protocol, values in found["rwt"].items():
        ours = statistics.median(values)
        base_values = found.get("base", {}).get(protocol)
        if base_values:
            base = statistics.median(base_values)
            lines.append(f"| {protocol} | {ours:.1f} | {base:.1f} | {ours / base:.3f} |")
        else:
            lines.append(f"| {protocol} | {ours:.1f} | | |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """The command line (the module's docstring)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.fanout_inproc")
    parser.add_argument("--base-src", help="another checkout's src directory (kind base)")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--sessions", type=int, default=100)
    parser.add_argument("--publishes", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=REPEATS)
    parser.add_argument("--protocols", nargs="+", default=list(PROTOCOLS), choices=PROTOCOLS)
    parser.add_argument("--smoke", action="store_true", help="tiny counts, one round")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.smoke:
        args.rounds, args.sessions, args.publishes, args.repeats = 1, 3, 5, 1
    if args.worker:
        _worker(args.protocols, args.sessions, args.publishes, args.repeats)
        return
    print(_table(compare(args)))


if __name__ == "__main__":
    main()
