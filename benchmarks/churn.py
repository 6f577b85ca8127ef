"""B26: a churn soak. One ``rwt serve`` for minutes or hours under clients that come and go.

``python -m benchmarks.churn [--minutes 60] [--rate FRONT=HZ ...] [--only FRONT ...]
[--ros2/--no-ros2] [--sample-s 10] [--out DIR] [--serve-arg ARG ...] [--wrap CMD]
[--trace FRAMES]``

One ``rwt serve --mcp --webrtc`` (``--ros2`` too where rclpy imports: the ROS 2 link)
and, for the whole run, a robot and a steady subscriber (``benchmarks/churn_steady.py``,
a process of its own: the robot publishes ``/soak/steady`` at 20 Hz and serves
``/soak/set_bool``; the subscriber counts every message and reports what it missed and
its silences). Then every front end churns, one cycle after another at its rate
(``RATES``; ``--rate FRONT=HZ`` changes one), each cycle a real client that connects,
advertises, subscribes, publishes, calls the service and leaves
(``benchmarks/churn_fronts.py``): rosbridge, Foxglove, the HTTP API, MCP, WebRTC, and
with ``--ros2`` WebSocket subscribers of a ROS 2 topic (the link's rclpy subscription
made and dropped) beside rclpy nodes that come and go (``benchmarks/churn_ros2.py``).

Every ``--sample-s`` the server's resident memory (``VmRSS`` of ``/proc/PID/status``),
CPU, open descriptors and threads are read, with each front end's cycles so far and the
steady subscriber's count: the curve, written as it goes to ``churn.csv`` in ``--out``
(``benchmarks/results/`` by default), and at the end ``churn.json`` with the summary:
RSS after the warm-up (``--warmup-minutes``, a fifth of the run up to 5 minutes) and at
the end (medians of the samples in a window of a minute at most), their difference in
MB and %, the slope after the warm-up (MB an hour, and bytes a cycle), cycles and
failures per front end, the steady subscriber's delivery, and the server's log of
warnings and errors. The verdict is that of docs/benchmarks.md, B26: the end within
5 % or 10 MB of the RSS after the warm-up, the steady subscriber missing nothing.

The default rates fit in a share of 2 cores beside the server (load and server
together under one core here); ``--trace FRAMES`` runs the server under
``benchmarks/churn_trace.py`` and prints what grew between the warm-up and the end: the
heap's figures (glibc's, pymalloc's), with ``FRAMES`` above 0 what tracemalloc traced,
by traceback, and the objects by type (a debugging run: its speed means nothing).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import csv
import importlib.util
import json
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from .churn_fronts import CYCLES, Target
from .ros2_bridge import ros_env
from .servers import ROOT, proc_stats, rwt_pythonpath, stop_process

__all__ = ["RATES", "Config", "main", "rclpy_imports", "ros2_environment", "run"]

RESULTS = ROOT / "benchmarks" / "results"
RATES = {
    "rosbridge": 4.0,
    "foxglove": 2.0,
    "http": 2.0,
    "mcp": 1.0,
    "webrtc": 0.5,
    "ros2-link": 1.0,
    "ros2": 0.5,
}
"""Cycles a second of each front end, one after another (a slow cycle delays the next;
none is made up). ``ros2`` is the rclpy peer's node churn, ``ros2-link`` WebSocket
subscribers of a ROS 2 topic; both need ``--ros2``."""
ROS2_FRONTS = ("ros2-link", "ros2")
CYCLE_S = 60.0
"""Bound on one cycle: a hang is a failure of the cycle, and the front end goes on."""
START_S = 120.0
"""Bound on a helper process's start (rclpy's discovery on a loaded machine)."""
DOMAINS = (60, 90)
"""The ROS 2 domain of a run's processes (``--domain``) is picked in this range by the
process id, so that two soaks at once (on ROS 2 they would bridge each other's
``/soak/steady``) most likely do not share one; the other benchmarks use 100-149, the
tests from 150, the soak's smoke test 90-94."""


def _domain() -> int:
    return DOMAINS[0] + os.getpid() % (DOMAINS[1] - DOMAINS[0])


@dataclass
class Config:
    """One run's settings (the command line's options)."""

    minutes: float = 60.0
    warmup_minutes: float | None = None
    sample_s: float = 10.0
    rates: dict[str, float] = field(default_factory=lambda: dict(RATES))
    ros2: bool | None = None
    """None: on where rclpy imports."""
    steady_hz: float = 20.0
    drain_s: float = 10.0
    out: Path = RESULTS
    domain: int = field(default_factory=_domain)
    ros2_steps: str = "sub,pub,call"
    """What a ``ros2`` cycle's node does (``benchmarks/churn_ros2.py --steps``)."""
    serve_args: list[str] = field(default_factory=list)
    """More options of ``rwt serve`` (``--serve-arg=--heap-keep=0``)."""
    wrap: list[str] = field(default_factory=list)
    """A command the server runs under (``--wrap "heaptrack -o /tmp/h"``)."""
    trace_frames: int | None = None
    """None: no tracing; 0: the heap's figures only; N: tracemalloc, N frames a traceback."""

    @property
    def warmup_s(self) -> float:
        """Seconds of warm-up: ``warmup_minutes``, else a fifth of the run up to 5 minutes."""
        if self.warmup_minutes is not None:
            return self.warmup_minutes * 60
        return min(300.0, self.minutes * 12)


@dataclass
class Front:
    """One front end's tally."""

    name: str
    hz: float
    cycles: int = 0
    failures: Counter[str] = field(default_factory=Counter)

    @property
    def failed(self) -> int:
        """Cycles that failed."""
        return sum(self.failures.values())


def ros2_environment(domain: int) -> dict[str, str] | None:
    """The environment of a ROS 2 run's processes, or None where rclpy is not installed.

    ``benchmarks.ros2_bridge.ros_env`` (a private domain, discovery on this host, the
    tests' Fast DDS profile), and the ROS 2 wheels' libraries on the library path: PyPI's
    ``ros-kilted-*`` wheels set it from a ``.pth`` file that looks under ``sys.prefix``,
    which in a virtualenv over the system's packages is the virtualenv, not where the
    wheels lie (their ``ros_*.libs`` folders and the ``lib`` folder of their prefix).
    """
    spec = importlib.util.find_spec("rclpy")
    if spec is None or spec.origin is None:
        return None
    site = Path(spec.origin).resolve().parent.parent
    libs = [str(p) for p in sorted(site.glob("ros_*.libs"))] + [str(site.parents[1])]
    env = {**os.environ, **ros_env(domain)}
    env["LD_LIBRARY_PATH"] = os.pathsep.join(
        filter(None, [*libs, os.environ.get("LD_LIBRARY_PATH")])
    )
    return env


def rclpy_imports(env: dict[str, str]) -> bool:
    """Whether rclpy and the messages the peer uses import in ``env`` (another process)."""
    probe = [sys.executable, "-c", "import rclpy, std_srvs.srv"]
    return subprocess.run(probe, env=env, capture_output=True, check=False).returncode == 0


class Helper:
    """A process of the run (server, steady process, rclpy peer) whose stdout lines are
    read by a thread: ``first`` is its first line that starts with ``ready`` (a wrapper's
    own lines before it are skipped), ``last`` its latest JSON line."""

    def __init__(
        self,
        cmd: list[str],
        env: dict[str, str],
        stderr: IO[bytes] | int,
        on_line: Callable[[dict[str, Any]], None] | None = None,
        ready: str = "",
    ) -> None:
        self.proc = subprocess.Popen(
            cmd,
            cwd=ROOT,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=stderr,
            start_new_session=True,  # a wrapper's children too are stopped (``stop``)
        )
        self.pid = self.proc.pid
        """The process to signal: the server under a ``--wrap`` (``_server_pid``)."""
        self.first: str | None = None
        self.last: dict[str, Any] = {}
        self._on_line = on_line
        self._prefix = ready
        self._ready = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for raw in self.proc.stdout:
            line = raw.decode("utf-8", "replace").strip()
            if self.first is None:
                if line.startswith(self._prefix):
                    self.first = line
                    self._ready.set()
            elif line.startswith("{"):
                self.last = json.loads(line)
                if self._on_line is not None:
                    self._on_line(self.last)
        self._ready.set()

    def wait_first(self, what: str, within: float = START_S) -> str:
        """Its first line; RuntimeError if it ended or said nothing within ``within`` s."""
        if not self._ready.wait(within) or self.first is None:
            stop_process(self.proc)
            raise RuntimeError(f"{what} did not start (status {self.proc.poll()})")
        return self.first

    def stop(self, grace_s: float = 15.0) -> None:
        """SIGTERM to ``pid``, then wait; past ``grace_s``, SIGKILL to its process group."""
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGTERM)
            try:
                self.proc.wait(grace_s)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        self._reader.join(5)
        if self.proc.stdout is not None and not self._reader.is_alive():
            self.proc.stdout.close()


def _server_pid(pid: int) -> int:
    """The ``rwt`` process under ``pid``: itself, or under ``--wrap`` the first descendant
    that runs Python (heaptrack and valgrind run the command as a child, beside their own)."""
    todo = [pid]
    while todo:
        here = todo.pop(0)
        with contextlib.suppress(OSError):
            with open(f"/proc/{here}/cmdline", "rb") as f:
                if b"python" in f.read().split(b"\0")[0]:
                    return here
            with open(f"/proc/{here}/task/{here}/children", encoding="ascii") as f:
                todo += [int(child) for child in f.read().split()]
    return pid


def _proc_counts(pid: int) -> tuple[int, int]:
    """Open descriptors and threads of a process."""
    fds = len(os.listdir(f"/proc/{pid}/fd"))
    with open(f"/proc/{pid}/status", encoding="ascii") as f:
        threads = next(int(ln.split()[1]) for ln in f if ln.startswith("Threads:"))
    return fds, threads


class Sampler:
    """Reads the server's figures every ``sample_s`` into rows, each written to the CSV."""

    def __init__(
        self, pid: int, fronts: dict[str, Front], steady: Helper, csv_file: IO[str]
    ) -> None:
        self.pid = pid
        self.fronts = fronts
        self.steady = steady
        self.rows: list[dict[str, Any]] = []
        self.start = time.monotonic()
        self._cpu = (self.start, proc_stats(pid).cpu_s)
        self._csv = csv_file
        self._writer: csv.DictWriter[str] | None = None

    def sample(self, phase: str) -> dict[str, Any]:
        """One row: time (s from the start), RSS (MB), CPU (% of a core since the last
        row), descriptors, threads, cycles and failures so far, the steady count."""
        now, stats = time.monotonic(), proc_stats(self.pid)
        fds, threads = _proc_counts(self.pid)
        cpu = (stats.cpu_s - self._cpu[1]) / max(now - self._cpu[0], 1e-9) * 100
        self._cpu = (now, stats.cpu_s)
        row: dict[str, Any] = {
            "t_s": round(now - self.start, 2),
            "phase": phase,
            "rss_mb": round(stats.rss_bytes / 1024 / 1024, 2),
            "cpu_pct": round(cpu, 1),
            "fds": fds,
            "threads": threads,
            **{f"cycles_{name}": front.cycles for name, front in self.fronts.items()},
            "failures": sum(front.failed for front in self.fronts.values()),
            "steady_got": self.steady.last.get("got", 0),
            "steady_missing": self.steady.last.get("missing", 0),
        }
        if self._writer is None:
            self._writer = csv.DictWriter(self._csv, fieldnames=list(row))
            self._writer.writeheader()
        self._writer.writerow(row)
        self._csv.flush()
        self.rows.append(row)
        return row


def _kind(exc: BaseException) -> str:
    text = str(exc).splitlines()[0] if str(exc) else ""
    return f"{type(exc).__name__}: {text}"[:160]


async def _drive(front: Front, target: Target, stop: asyncio.Event) -> None:
    """``front``'s cycles, one after another at its rate, until ``stop``."""
    cycle = CYCLES[front.name]
    due, n = time.monotonic(), 0
    while not stop.is_set():
        try:
            async with asyncio.timeout(CYCLE_S):
                await cycle(target, n)
            front.cycles += 1
        except Exception as exc:  # a failed cycle is a figure, not an end
            front.failures[_kind(exc)] += 1
        n += 1
        due = max(due + 1.0 / front.hz, time.monotonic())
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), due - time.monotonic())


async def _churn(
    config: Config,
    target: Target,
    sampler: Sampler,
    trace: Tracer | None,
    peer: Helper | None,
) -> None:
    """The churn for ``config.minutes``, sampled; then the drain (the rclpy ``peer``
    stopped, its nodes gone), sampled too."""
    stop = asyncio.Event()
    drivers = [
        asyncio.ensure_future(_drive(front, target, stop))
        for front in sampler.fronts.values()
        if front.name in CYCLES
    ]
    end = sampler.start + config.minutes * 60
    traced = False
    while time.monotonic() < end:
        await asyncio.sleep(min(config.sample_s, max(0.0, end - time.monotonic())))
        sampler.sample("churn")
        if trace is not None and not traced and time.monotonic() - sampler.start >= config.warmup_s:
            traced = True
            await trace.snapshot()
    stop.set()
    if drivers:
        await asyncio.wait(drivers, timeout=CYCLE_S + 5)
    if peer is not None:
        await asyncio.to_thread(peer.stop, CYCLE_S)  # its cycle in flight ends first
    drain_end = time.monotonic() + config.drain_s
    while time.monotonic() < drain_end:
        await asyncio.sleep(min(config.sample_s, max(0.0, drain_end - time.monotonic())))
        sampler.sample("drain")
    if trace is not None:
        await trace.snapshot()


class Tracer:
    """Asks the server under ``churn_trace`` for a snapshot (SIGUSR2) and waits for it."""

    def __init__(self, pid: int, folder: Path) -> None:
        self.pid = pid
        self.folder = folder
        self.taken = 0

    async def snapshot(self) -> None:
        """Snapshot ``taken`` (0, 1...); waits up to 10 minutes for it."""
        done = self.folder / f"done-{self.taken}"
        os.kill(self.pid, signal.SIGUSR2)
        for _ in range(1200):  # 10 minutes at most
            if done.exists():
                break
            await asyncio.sleep(0.5)
        self.taken += 1


def _fronts(config: Config, ros2: bool) -> dict[str, Front]:
    return {
        name: Front(name, hz)
        for name, hz in config.rates.items()
        if hz > 0 and (ros2 or name not in ROS2_FRONTS)
    }


def _want_ros2(config: Config, env: dict[str, str]) -> dict[str, str] | None:
    """The ROS 2 run's environment, or None for a run without ``--ros2``.

    Raises:
        RuntimeError: ``--ros2`` was asked for and rclpy does not import.
    """
    if config.ros2 is False or not any(config.rates.get(f, 0) > 0 for f in ROS2_FRONTS):
        return None
    ros = ros2_environment(config.domain)
    if ros is not None and rclpy_imports({**ros, **_own(env)}):
        return {**ros, **_own(env)}
    if config.ros2:
        raise RuntimeError("--ros2: rclpy (or std_srvs) does not import here")
    return None


def _own(env: dict[str, str]) -> dict[str, str]:
    return {k: env[k] for k in ("PYTHONPATH", "PYTHONUNBUFFERED")}


def _ros2_tally(front: Front) -> Callable[[dict[str, Any]], None]:
    def on_line(line: dict[str, Any]) -> None:
        if line.get("ok"):
            front.cycles += 1
        elif "error" in line:
            front.failures[str(line["error"])[:160]] += 1

    return on_line


def _import_clients(fronts: dict[str, Front]) -> None:
    """Import the optional clients now: seconds of CPU that would stall the first cycles."""
    if "mcp" in fronts:
        import mcp.client.streamable_http  # noqa: F401, PLC0415
    if "webrtc" in fronts:
        import aiortc  # noqa: F401, PLC0415


def _client_count(target: Target) -> Any:
    """``/client_count`` through the HTTP API (this request's connection counts too)."""
    import httpx  # noqa: PLC0415

    try:
        return httpx.get(f"{target.http}/api/topics/client_count", timeout=10).json()
    except (httpx.HTTPError, ValueError) as exc:
        return f"unread: {exc}"


def run(config: Config) -> dict[str, Any]:
    """One soak (module docstring); its record, also written to ``config.out``/churn.json."""
    from .churn_report import log_summary, summarize, trace_growth, verdict  # noqa: PLC0415

    config.out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": rwt_pythonpath(), "PYTHONUNBUFFERED": "1"}
    ros = _want_ros2(config, env)
    fronts = _fronts(config, ros is not None)
    _import_clients(fronts)
    serve = ["serve", "--port", "0", "--mcp", "--webrtc", "--log-level", "warning"]
    serve += ["--ros2", "--ros2-node-name", "rwt_soak"] if ros is not None else []
    serve += config.serve_args
    with tempfile.TemporaryDirectory(prefix="rwt-churn-") as tmp, contextlib.ExitStack() as stack:
        log_path = Path(tmp) / "server.log"
        log = stack.enter_context(open(log_path, "wb"))
        cmd = [*config.wrap, sys.executable, "-m", "rwt", *serve]
        if config.trace_frames is not None:
            cmd = [*config.wrap, sys.executable, "-m", "benchmarks.churn_trace"]
            cmd += [str(config.trace_frames), tmp]
            cmd += serve
        server = Helper(cmd, ros or env, log, ready="listening on ")
        stack.callback(server.stop)
        url = server.wait_first("rwt serve").removeprefix("listening on ")
        server.pid = _server_pid(server.proc.pid)
        target = Target(url)
        steady_cmd = [sys.executable, "-m", "benchmarks.churn_steady", url]
        steady = Helper([*steady_cmd, "--hz", str(config.steady_hz)], env, subprocess.DEVNULL)
        stack.callback(steady.stop)
        if steady.wait_first("the steady subscriber") != "ready":
            raise RuntimeError(f"the steady subscriber said {steady.first!r}")
        peer = None
        if ros is not None:
            hz = str(fronts["ros2"].hz if "ros2" in fronts else 0)
            peer_cmd = [sys.executable, "-m", "benchmarks.churn_ros2", "--hz", hz]
            peer_cmd += ["--steps", config.ros2_steps]
            peer = Helper(
                peer_cmd, ros, subprocess.DEVNULL, _ros2_tally(fronts.get("ros2", Front("ros2", 0)))
            )
            stack.callback(peer.stop)
            peer.wait_first("the rclpy peer")
        csv_file = stack.enter_context(open(config.out / "churn.csv", "w", newline=""))
        sampler = Sampler(server.pid, fronts, steady, csv_file)
        sampler.sample("churn")
        load0 = time.process_time()
        tracer = Tracer(server.pid, Path(tmp)) if config.trace_frames is not None else None
        asyncio.run(_churn(config, target, sampler, tracer, peer))
        load_cpu = (time.process_time() - load0) / max(time.monotonic() - sampler.start, 1e-9)
        clients = _client_count(target)
        stack.close()  # the helpers stop: the steady subscriber's last line
        growth = trace_growth(Path(tmp)) if tracer is not None else None
        record: dict[str, Any] = {
            "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "load_average": os.getloadavg(),
            "config": {**vars(config), "out": str(config.out), "ros2": ros is not None},
            "server": " ".join(["rwt", *serve]),
            "summary": summarize(sampler.rows, config.warmup_s, list(fronts)),
            "fronts": {
                n: {
                    "hz": f.hz,
                    "cycles": f.cycles,
                    "failed": f.failed,
                    "failures": dict(f.failures.most_common()),
                }
                for n, f in fronts.items()
            },
            "steady": steady.last,
            "client_count_after_drain": clients,
            "load_cpu_pct": round(load_cpu * 100, 1),
            "log": log_summary(log_path.read_text("utf-8", "replace")),
            "trace": growth,
        }
    record["verdict"] = verdict(record["summary"], record["steady"])
    (config.out / "churn.json").write_text(
        json.dumps({**record, "samples": sampler.rows}, indent=1) + "\n"
    )
    return record


def _rates(given: list[str]) -> dict[str, float]:
    rates = dict(RATES)
    for item in given:
        name, _, hz = item.partition("=")
        if name not in rates:
            raise SystemExit(f"--rate {item}: no front end {name!r} (one of {', '.join(rates)})")
        rates[name] = float(hz)
    return rates


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """The command line (module docstring); prints the summary and returns the record."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--warmup-minutes", type=float)
    parser.add_argument("--sample-s", type=float, default=10.0)
    parser.add_argument("--rate", action="append", default=[], metavar="FRONT=HZ")
    parser.add_argument("--only", action="append", default=[], metavar="FRONT")
    parser.add_argument("--ros2", action=argparse.BooleanOptionalAction, default=None)
    parser.add_argument("--steady-hz", type=float, default=20.0)
    parser.add_argument("--drain-s", type=float, default=10.0)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--domain", type=int, default=_domain())
    parser.add_argument("--ros2-steps", default="sub,pub,call")
    parser.add_argument("--serve-arg", action="append", default=[], metavar="ARG")
    parser.add_argument("--wrap", default="", metavar="CMD")
    parser.add_argument("--trace", type=int, metavar="FRAMES")
    args = parser.parse_args(argv)
    rates = _rates(args.rate)
    if args.only:
        unknown = set(args.only) - set(rates)
        if unknown:
            raise SystemExit(f"--only {', '.join(sorted(unknown))}: one of {', '.join(rates)}")
        rates = {name: (hz if name in args.only else 0.0) for name, hz in rates.items()}
    config = Config(
        minutes=args.minutes,
        warmup_minutes=args.warmup_minutes,
        sample_s=args.sample_s,
        rates=rates,
        ros2=args.ros2,
        steady_hz=args.steady_hz,
        drain_s=args.drain_s,
        out=args.out,
        domain=args.domain,
        ros2_steps=args.ros2_steps,
        serve_args=args.serve_arg,
        wrap=shlex.split(args.wrap),
        trace_frames=args.trace,
    )
    record = run(config)
    from .churn_report import table  # noqa: PLC0415

    print(table(record))
    if record["trace"]:
        print(record["trace"])
    return record


if __name__ == "__main__":
    main()
