"""``python -m benchmarks scaleout --workers 1,2,4 --fanouts K``: what ``--workers N`` buys.

For each worker count N, one server (N = 1: a plain ``rwt serve``; else ``rwt
serve --workers N``) and K parallel fan-outs, each 1 publisher and S subscribers
(``--subscribers``, default 50) on a topic of its own (``/fan0`` ...). Each
fan-out is driven by a generator process of its own (the suite's raw-socket
generator, ``fanout_raw.FanOut``: a stream of 100 B ``std_msgs/String`` paced by a
window of 512 messages ahead of its slowest subscriber, so nothing is dropped),
connected and probed until every subscriber is reached; then all K bursts start
together and last ``--duration`` seconds.

Two more loads, for the many-connections and many-topics cases of docs/scaling.md:
``--topics-per-fanout T`` makes each generator drive T fan-outs (a topic each, every
burst in its one loop: K x T topics in all); ``--idle N`` adds N idle clients in a
process of their own, each a connection with a subscription to a topic nothing
publishes (a dashboard that waits), connected before the bursts and held through them
(the open-file limit is raised for it within the hard limit, since the server sizes
``--max-connections`` from it). ``--placement topic`` runs the servers of more than one
worker with ``--placement topic`` (D57: a topic's connections on the worker that owns
it), so a topic's messages stay in one worker.

Per worker count the table gives:

- deliveries/s: every delivery of the K bursts over the time from the first
  timed send to the last delivery (all generators read one monotonic clock);
- x one worker: over the first row's figure (the smallest worker count);
- server CPU per delivery (us): every thread of every process of the server
  (the supervising parent and its workers) from ``/proc``, from just before the
  bursts start to just after the last delivery, over the deliveries; set-up
  (connections, subscriptions, probes) is not counted;
- server cores: deliveries/s x CPU per delivery, the cores the server kept busy
  (below the workers' count and the machine's free cores, something else bounds
  the figure: the window against the latency of a message's path);
- the generators' own CPU: in cores (their CPU seconds over the timed wall) and in
  us per delivery, so a reader sees when the generators, not the server, bound
  the figure (on a machine with fewer free cores than K + N they share them);
- delivered / expected and dropped (must be 0);
- the server's resident memory (every process, after set-up, before the bursts).

Ratios carry over to another machine, absolutes do not; CPU time on a shared
virtual machine drifts by up to a factor of two from one minute to the next
(benchmarks/JOURNAL.md, "Workers' CPU per delivery"), so compare rows of one run.
``benchmarks/results/scaleout_workers.json`` keeps every figure.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import resource
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from . import msgs
from .fanout_raw import STRING, FanOut
from .loadgen.engine import GeneratorError, run_loop
from .loadgen.wire import client_frame, connect
from .proctree import tree_cpu_ns
from .servers import rwt_pythonpath, stop_process

__all__ = ["ScaleRow", "main", "measure", "scale_table", "serve_workers"]

RESULTS = Path(__file__).resolve().parent / "results" / "scaleout_workers.json"
START_TIMEOUT_S = 120.0
"""How long a server and its workers get to listen, and the generators to set up, seconds."""
IDLE_CONNECT_S = 0.03
"""More set-up time per idle client (``--idle``), seconds: 10,000 took 60 s to connect
and subscribe to two workers on the 2-core machine, under load."""
STALL_S = 5.0
"""A burst with no delivery for this long is over: what is missing was dropped, seconds."""


@dataclass(frozen=True)
class ScaleRow:
    """One worker count's figures (see the module's docstring)."""

    workers: int
    fanouts: int
    subscribers: int
    deliveries_per_s: float
    server_us_per_delivery: float
    generator_cores: float
    generator_us_per_delivery: float
    delivered: int
    expected: int
    topics: int = 1
    """fan-outs per generator, a topic each"""
    idle: int = 0
    """idle clients beside them (a connection and a subscription to a quiet topic each)"""
    server_rss_bytes: int = 0
    """resident memory of the server's processes after set-up, before the bursts"""
    placement: str = "none"
    """``--placement`` of a server of more than one worker (D57)"""

    @property
    def dropped(self) -> int:
        """Deliveries expected (messages sent x subscribers) that never came."""
        return self.expected - self.delivered


@contextlib.contextmanager
def serve_workers(workers: int, extra: Sequence[str] = ()) -> Iterator[tuple[int, int]]:
    """``rwt serve`` with ``workers`` workers (1: a plain server); yields (pid, port).

    ``extra``: more ``serve`` options (``--mcp``).

    Returns once the server says it listens: with workers, once every worker accepts
    from the parent's listening socket (docs/scaling.md), so the connections spread
    over all of them.

    Raises:
        RuntimeError: the server did not start.
    """
    cmd = [sys.executable, "-m", "rwt", "serve", "--port", "0", "--no-tf"]
    cmd += ["--log-level", "warning", *(["--workers", str(workers)] if workers > 1 else [])]
    cmd += extra
    env = {**os.environ, "PYTHONPATH": rwt_pythonpath(), "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, env=env)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline().decode().strip()
        if not line.startswith("listening on "):
            raise RuntimeError(f"rwt serve did not start: {line!r}")
        port = int(line.rsplit(":", 1)[1].split("/")[0])
        yield proc.pid, port
    finally:
        stop_process(proc)


def _generator(
    port: int, subscribers: int, topics: list[str], duration_s: float, pipe: Connection
) -> None:
    """Fan-outs (one per topic) in a process of its own: set up, say ``ready``, wait for
    ``go``, burst them all together in one loop.

    Sends back (delivered, expected, first send, last delivery (``perf_counter``, s),
    CPU s), then waits for ``close`` before closing its connections (their teardown
    is not the burst's). A set-up error is sent back as its text.
    """
    fans: list[FanOut] = []
    try:
        for topic in topics:
            fans.append(FanOut(port, subscribers, topic))
    except (GeneratorError, OSError) as error:
        pipe.send(f"{type(error).__name__}: {error}")
        for fan in fans:
            fan.close()
        return
    pubs = [fan.pub for fan in fans]
    subs = [sub for fan in fans for sub in fan.subs]
    pipe.send("ready")
    pipe.recv()
    for pub in pubs:
        pub.duration_s = duration_s
    for sub in subs:
        sub.first_s = sub.last_s = None
        sub.received = 0

    def done() -> bool:
        if not all(pub.finished for pub in pubs):
            return False
        last = max((s.last_s or 0.0 for s in subs), default=0.0)
        stopped = max(pub.stop_s or 0.0 for pub in pubs)
        stalled = time.perf_counter() - max(last, stopped) > STALL_S
        return stalled or all(s.received >= f.pub.sent for f in fans for s in f.subs)

    loop = run_loop(pubs, subs, done=done, limit_s=duration_s + 120.0)
    delivered = sum(s.received for s in subs)
    expected = sum(fan.pub.sent * len(fan.subs) for fan in fans)
    last = max((s.last_s or 0.0 for s in subs), default=0.0)
    first = min(pub.first_s or 0.0 for pub in pubs)
    pipe.send((delivered, expected, first, last, loop.generator_cpu_s))
    pipe.recv()
    for fan in fans:
        fan.close()


def _idle_holder(port: int, count: int, pipe: Connection) -> None:
    """``count`` idle clients in a process of its own: each a WebSocket connection with
    one subscription to a topic nothing publishes (``/quiet``), as a dashboard that
    waits holds; says ``ready`` once all are subscribed, closes them on ``close``."""
    socks: list[socket.socket] = []
    try:
        frame = client_frame(msgs.subscribe("/quiet", STRING))
        for _ in range(count):
            sock, _rest = connect(port)
            sock.sendall(frame)
            socks.append(sock)
    except OSError as error:
        pipe.send(f"{type(error).__name__}: {error}")
    else:
        pipe.send("ready")
        pipe.recv()
    for sock in socks:
        sock.close()


def _raise_fd_limit(wanted: int) -> None:
    """The soft open-file limit raised towards ``wanted`` (within the hard one), for this
    process and what it starts: the server sizes ``--max-connections`` from it."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
    if soft != resource.RLIM_INFINITY and soft < target:
        resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))


def tree_rss_bytes(pid: int) -> int:
    """Resident memory of ``pid`` and its live descendants, bytes (``/proc``)."""
    total, pending, seen = 0, [pid], set()
    while pending:
        current = pending.pop()
        if current in seen:
            continue
        seen.add(current)
        with contextlib.suppress(OSError, ValueError):
            for line in Path(f"/proc/{current}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) * 1024
            for task in Path(f"/proc/{current}/task").iterdir():
                pending += [int(c) for c in (task / "children").read_text().split()]
    return total


def measure(
    workers: int,
    fanouts: int,
    subscribers: int,
    duration_s: float,
    *,
    topics: int = 1,
    idle: int = 0,
    placement: str = "none",
) -> ScaleRow:
    """One server of ``workers`` workers under ``fanouts`` parallel generators, each
    driving ``topics`` fan-outs (a topic each), beside ``idle`` idle clients (module doc).

    Raises:
        RuntimeError: the server did not start, or a generator failed to set up.
    """
    # fork: a generator starts in milliseconds, whatever ran this (a script on stdin,
    # pytest); this process has no threads of its own to fork with
    context = multiprocessing.get_context("fork")
    if idle:
        _raise_fd_limit(2 * (idle + fanouts * topics * (subscribers + 1)) + 4096)
    if workers == 1:
        placement = "none"  # one worker: nowhere to place
    with serve_workers(workers, ["--placement", placement] if workers > 1 else []) as (pid, port):
        pipes: list[Connection] = []
        procs = []
        jobs: list[tuple[Any, tuple[Any, ...]]] = [
            (_generator, (port, subscribers, [f"/fan{i * topics + t}" for t in range(topics)]))
            for i in range(fanouts)
        ]
        if idle:
            jobs.append((_idle_holder, (port, idle)))
        for target, args in jobs:
            mine, theirs = context.Pipe()
            extra = (duration_s, theirs) if target is _generator else (theirs,)
            proc = context.Process(target=target, args=(*args, *extra))
            proc.start()
            theirs.close()  # the child's end, its copy is the child's
            pipes.append(mine)
            procs.append(proc)
        generators = pipes[:fanouts]
        try:
            deadline = time.monotonic() + START_TIMEOUT_S + idle * IDLE_CONNECT_S
            for pipe in pipes:
                ready = pipe.poll(max(0.0, deadline - time.monotonic()))
                answer = pipe.recv() if ready else "no answer"
                if answer != "ready":
                    raise RuntimeError(f"a generator failed: {answer}")
            time.sleep(0.5)  # probes still in flight land before the bursts
            rss = tree_rss_bytes(pid)
            before = tree_cpu_ns(pid)
            for pipe in generators:
                pipe.send("go")
            found = [pipe.recv() for pipe in generators]
            server_ns = tree_cpu_ns(pid) - before
            for pipe in pipes:
                pipe.send("close")
        finally:
            for proc in procs:
                proc.join(30)
                if proc.is_alive():
                    proc.kill()
                    proc.join()
                proc.close()
            for pipe in pipes:
                pipe.close()
    delivered = sum(f[0] for f in found)
    wall = max(f[3] for f in found) - min(f[2] for f in found)
    generator_s = sum(f[4] for f in found)
    return ScaleRow(
        workers=workers,
        fanouts=fanouts,
        subscribers=subscribers,
        deliveries_per_s=delivered / wall,
        server_us_per_delivery=server_ns / 1e3 / max(delivered, 1),
        generator_cores=generator_s / wall,
        generator_us_per_delivery=generator_s * 1e6 / max(delivered, 1),
        delivered=delivered,
        expected=sum(f[1] for f in found),
        topics=topics,
        idle=idle,
        server_rss_bytes=rss,
        placement=placement,
    )


def scale_table(rows: list[ScaleRow]) -> str:
    """The rows as a Markdown table, ratios against the first row."""
    base = rows[0]
    lines = [
        "| workers | fan-outs x subscribers | deliveries/s | x first row | "
        "server CPU us/delivery | x first row | server cores | generators: cores; us/delivery | "
        "delivered/expected | dropped | server RSS MB |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        load = f"{row.fanouts} x {row.subscribers}"
        if row.topics > 1:
            load = f"{row.fanouts} x {row.topics} topics x {row.subscribers}"
        if row.idle:
            load += f" + {row.idle:,} idle"
        placed = " (placed by topic)" if row.placement == "topic" else ""
        lines.append(
            f"| {row.workers}{placed} | {load} | "
            f"{row.deliveries_per_s:,.0f} | {row.deliveries_per_s / base.deliveries_per_s:.2f} | "
            f"{row.server_us_per_delivery:.2f} | "
            f"{row.server_us_per_delivery / base.server_us_per_delivery:.2f} | "
            f"{row.deliveries_per_s * row.server_us_per_delivery / 1e6:.2f} | "
            f"{row.generator_cores:.2f}; {row.generator_us_per_delivery:.2f} | "
            f"{row.delivered:,}/{row.expected:,} | {row.dropped} | "
            f"{row.server_rss_bytes / 2**20:,.0f} |"
        )
    return "\n".join(lines)


def main(
    workers: list[int],
    fanouts: int,
    subscribers: int,
    duration_s: float,
    *,
    smoke: bool = False,
    out: Path | None = None,
    topics: int = 1,
    idle: int = 0,
    placement: str = "none",
) -> int:
    """Measure each worker count in turn, print the table; exit status 1 if any dropped.

    ``smoke``: 0.3 s bursts and nothing saved.
    """
    rows = []
    for count in workers:
        print(f"workers {count}", file=sys.stderr, flush=True)
        duration = 0.3 if smoke else duration_s
        rows.append(
            measure(
                count, fanouts, subscribers, duration, topics=topics, idle=idle, placement=placement
            )
        )
    print(scale_table(rows))
    if not smoke:
        record: dict[str, Any] = {"rows": [asdict(r) for r in rows], "duration_s": duration_s}
        (out or RESULTS).write_text(json.dumps(record, indent=2) + "\n", "utf-8")
    return 1 if any(r.dropped for r in rows) else 0
