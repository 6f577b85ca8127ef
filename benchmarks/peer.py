"""``python -m benchmarks peer``: rosbridge_suite (ROS 1), rwt (ROS 1 dialect) and the bare relay.

B1 (String 100 B, 1 -> 1), B2 (1 -> 10) and B7 (latency, String 100 B at 100 Hz,
1 -> 10) run against the three servers in one run, interleaved run by run (the
order rotates), with the same load generator and checks as the suite: every
delivered message is compared byte for byte with what rosbridge_suite or rwt
writes for it (``as_served``). Types are spelled the ROS 1 way (``std_msgs/String``).

The peer is a rosbridge_suite 0.11.x ``rosbridge_websocket`` already running,
given by ``RWT_ROSBRIDGE_ROS1_URL`` or ``--peer-url``; its CPU and memory are read
from /proc for the process listening on that port (rosbridge only, not roscore
or rosapi). Without a peer the command says so and exits 0.

ROS 1 links a subscriber to a publisher in the background, and rosbridge_suite
replays a new publisher's first second to late links (REF §5.4), which loses or
repeats messages at the start of a run. So for rosbridge_suite one extra
connection holds each topic for the whole scenario (advertised, and subscribed
with a throttle of an hour, so it gets one message), opened 1.5 s before the
first run: the runs then join a publisher and a subscription whose link exists. B7 runs at 100 Hz
rather than the suite's 1 kHz: 10,000 deliveries/s is beyond what rosbridge_suite
delivers (about 2,400 msg/s 1 -> 1 here), and its queue grows without bound.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from urllib.parse import urlsplit

from . import msgs
from .loadgen.engine import Peer
from .scenarios.common import Metrics, Run, summary
from .scenarios.latency import topic_latency_run
from .scenarios.throughput import Stream, stream_run
from .servers import ProcStats, Server, proc_stats, start_server

__all__ = ["PEER_ENV", "ExternalServer", "listening_pid", "main", "run_peer"]

PEER_ENV = "RWT_ROSBRIDGE_ROS1_URL"
KINDS = ("bare", "rwt", "rosbridge")
LABELS = {"bare": "bare relay", "rwt": "rwt serve --dialect ros1", "rosbridge": "rosbridge 0.11"}


class ExternalServer(Server):
    """A server this run did not start: measured by the pid listening on its port."""

    def __init__(self, kind: str, port: int, pid: int) -> None:
        self.kind = kind
        self.port = port
        self.pid = pid

    def stats(self) -> ProcStats:
        """CPU and memory of the listening process (``proc_stats``)."""
        return proc_stats(self.pid)

    def alive(self) -> bool:
        """Whether the process still exists."""
        return Path(f"/proc/{self.pid}").exists()

    def stop(self) -> None:
        """Nothing: the peer belongs to whoever started it."""


def listening_pid(port: int) -> int | None:
    """The pid of the process with a TCP socket listening on ``port`` (Linux /proc), or None."""
    inodes = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text("ascii").splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            cols = line.split()
            local, state, inode = cols[1], cols[3], cols[9]
            if state == "0A" and int(local.rsplit(":", 1)[1], 16) == port:  # 0A: LISTEN
                inodes.add(f"socket:[{inode}]")
    if not inodes:
        return None
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            fds = list((proc / "fd").iterdir())
        except OSError:  # gone, or not ours to read
            continue
        for fd in fds:
            try:
                if os.readlink(fd) in inodes:
                    return int(proc.name)
            except OSError:
                continue
    return None


@dataclass
class Scenario:
    """One row: a measurement run against each server."""

    key: str
    run: Callable[[Run], Metrics]
    primary: str
    unit: str
    topic: str
    runs: dict[str, list[Metrics]] = field(default_factory=dict)


STRING_ROS1 = Stream("/peer_b1", "std_msgs/String", partial(msgs.string_publish, "/peer_b1"))
_LATENCY_TOPIC = "/b7"  # topic_latency_run's
_HOLD_S = 1.5


def _scenarios(scale: float) -> list[Scenario]:
    def throughput(subscribers: int) -> Callable[[Run], Metrics]:
        return lambda run: stream_run(
            run, STRING_ROS1, subscribers=subscribers, duration_s=1.5 * scale
        )

    def latency(run: Run) -> Metrics:
        return topic_latency_run(
            run, subscribers=10, rate_hz=100.0, duration_s=3.0 * scale, type_name="std_msgs/String"
        )

    return [
        Scenario("B1 String 100 B, 1 -> 1", throughput(1), "msg_per_s", "msg/s", STRING_ROS1.topic),
        Scenario(
            "B2 String 100 B, 1 -> 10",
            throughput(10),
            "deliveries_per_s",
            "deliveries/s",
            STRING_ROS1.topic,
        ),
        Scenario("B7 String 100 B at 100 Hz, 1 -> 10", latency, "p50_ms", "ms", _LATENCY_TOPIC),
    ]


def run_peer(
    peer_url: str, runs: int, scale: float = 1.0, log: Callable[[str], None] = print
) -> list[Scenario]:
    """Run every scenario ``runs`` times against the three servers, interleaved.

    Raises:
        ConnectionError: nothing listens on the peer's port.
    """
    port = urlsplit(peer_url).port
    pid = None if port is None else listening_pid(port)
    if port is None or pid is None:
        raise ConnectionError(f"nothing listens on {peer_url}")
    scenarios = _scenarios(scale)
    peer = ExternalServer("rosbridge", port, pid)
    started = {
        "bare": start_server("bare"),
        "rwt": start_server("rwt", extra=["--dialect", "ros1"]),
    }
    servers: dict[str, Server] = {**started, "rosbridge": peer}
    try:
        for scenario in scenarios:
            scenario.runs = {kind: [] for kind in KINDS}
            log(scenario.key)
            holder = _hold(port, scenario.topic)
            for index in range(runs):
                order = KINDS[index % 3 :] + KINDS[: index % 3]
                for kind in order:
                    server = servers[kind]
                    if not server.alive():
                        raise RuntimeError(f"the {kind} server died")
                    metrics = scenario.run(Run(server, scale))
                    scenario.runs[kind].append(metrics)
                    value = metrics[scenario.primary]
                    log(f"    {kind} run {index + 1}: {scenario.primary}={value:,.4g}")
            holder.close()
    finally:
        for server in started.values():
            server.stop()
    return scenarios


def _hold(port: int, topic: str) -> Peer:
    """Hold ``topic`` on rosbridge_suite for a scenario (module docstring)."""
    hold = (
        f'{{"op":"subscribe","topic":"{topic}","type":"std_msgs/String",'
        f'"throttle_rate":3600000,"queue_length":0}}'
    ).encode()
    holder = Peer(
        port, "rosbridge", [msgs.advertise(topic, "std_msgs/String"), hold], receives=True
    )
    time.sleep(_HOLD_S)  # past the publisher's first second, and the link is made
    return holder


def table(scenarios: list[Scenario]) -> str:
    """Markdown: per scenario and server, the medians of the runs."""
    head = "| scenario | figure | " + " | ".join(LABELS[k] for k in KINDS) + " |"
    lines = [head, "|---|---|" + "---|" * len(KINDS)]
    for scenario in scenarios:
        medians = {kind: summary(runs) for kind, runs in scenario.runs.items()}
        figures = [(scenario.primary, scenario.unit, "{:,.0f}")]
        if scenario.primary == "p50_ms":
            figures = [("p50_ms", "p50 ms", "{:.2f}"), ("p99_ms", "p99 ms", "{:.2f}")]
        else:
            figures[0] = (scenario.primary, scenario.unit, "{:,.0f}")
            figures.append(("server_cpu_us_per_delivery", "server CPU us/delivery", "{:.1f}"))
        figures += [
            ("server_cpu_pct", "server CPU %", "{:.0f}"),
            ("server_rss_mb", "server RSS MB", "{:.0f}"),
        ]
        for metric, label, form in figures:
            cells = []
            for kind in KINDS:
                stats = medians[kind].get(metric)
                cells.append("-" if stats is None else form.format(stats["median"]))
            lines.append(f"| {scenario.key} | {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks peer [--runs N] [--peer-url URL] [--smoke]``.

    ``--edition ros2`` runs the ROS 2 edition instead (benchmarks/peer_ros2.py, its options).
    """
    argv = sys.argv[1:] if argv is None else argv
    if argv[:2] == ["--edition", "ros2"]:
        from .peer_ros2 import main as ros2_main  # noqa: PLC0415

        return ros2_main(argv[2:])
    if argv[:2] == ["--edition", "ros1"]:
        argv = argv[2:]
    parser = argparse.ArgumentParser(prog="python -m benchmarks peer", description=__doc__)
    parser.add_argument("--runs", type=int, default=3, help="runs per server and scenario")
    parser.add_argument("--peer-url", default=os.environ.get(PEER_ENV), help=f"default ${PEER_ENV}")
    parser.add_argument("--smoke", action="store_true", help="one tiny run (tests)")
    args = parser.parse_args(argv)
    if not args.peer_url:
        print(
            f"benchmarks peer: skipped: no rosbridge_suite (ROS 1) to compare with;"
            f" set {PEER_ENV} to a running rosbridge_websocket's URL",
            file=sys.stderr,
        )
        return 0
    runs, scale = (1, 0.2) if args.smoke else (args.runs, 1.0)

    def log(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    try:
        scenarios = run_peer(args.peer_url, runs, scale, log)
    except ConnectionError as exc:
        print(f"benchmarks peer: {exc}", file=sys.stderr)
        return 2
    print(table(scenarios))
    return 0
