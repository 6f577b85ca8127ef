"""``python -m benchmarks.ros2_bridge``: real ROS 2 to WebSocket clients through a bridge.

A real rclpy publisher (its own process, PyPI's ROS 2 Kilted wheels, Fast DDS set
up as ``FASTDDS`` says) publishes on a private domain; a bridge carries each message
to 1 or 10 WebSocket subscribers in this process (``CLIENTS``: by default
``ros2_client.LeanCounter``, which reads the stamp and checks each image in place;
``--client websockets``: the library, stamp only). Four receivers, in one run and on
one machine state:

- ``rwt``: ``rwt serve --ros2 --no-tf`` from this checkout (docs/ros2.md);
- ``rosbridge``: the real rosbridge_suite 2.1.0 for ROS 2 (``rosbridge_websocket``
  + ``rosapi_node``), restarted before each case because it slows down over time.
  It is found through ``RWT_ROSBRIDGE_ROS2_DIR``: the directory holding its
  ``start_rosbridge_ros2.sh PORT DOMAIN`` and ``stop.sh PORT``; unset, those cases
  are skipped and the report says why;
- ``rs``: rosbridge-server-rs 0.1.6 (Rust, a ROS 2 node on Jazzy wheels), found
  through ``RWT_ROSBRIDGE_RS_DIR`` (``start.sh PORT DOMAIN``, ``stop.sh PORT``),
  restarted before each case too;
- ``rclpy``: the ceiling, a bare rclpy subscription in its own process (one
  subscriber: ROS 2 delivers to each subscribing process on its own);
- ``before``: ``rwt`` again, from the ``src`` folder ``RWT_BEFORE_SRC`` names (a
  checkout of the code before a change), so a change is measured against the code
  before it in one run, round by round.

Messages: a 100 B ``std_msgs/msg/String`` (its data starts with the publish time,
``time.time()`` in seconds) published as fast as rclpy can and paced at
``FAST_HZ``, ``MID_HZ`` and ``PACED_HZ``; a 640x480 rgb8 ``sensor_msgs/msg/Image``
at 30 Hz (the header stamp is the publish time). Each case: the publisher sends probes until every
subscriber got one (discovery is eventual), then the timed messages for
``seconds``; a subscriber idle for ``IDLE_S`` has seen all it will.

Reported per case: delivered msg/s (all subscribers together, from the first
timed publish to the last delivery), loss (1 - deliveries / (sent x
subscribers)), p50 and p99 latency (receive wall time minus the stamp, one
machine, so one clock) and the receiving process's CPU per delivery in us (user
+ system from ``/proc/<pid>/stat``, read at the last delivery).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable, Sequence

from .ros2_client import TYPES, LeanCounter, stamp
from .servers import ROOT, Server, proc_stats, rwt_pythonpath, start_server

__all__ = [
    "CASES",
    "Case",
    "Result",
    "main",
    "rclpy_available",
    "run_case",
    "stage_counts",
    "stage_table",
    "summary",
    "table",
    "verdicts",
]


@dataclass(frozen=True, slots=True)
class PeerTools:
    """How a peer bridge starts: ``env`` names its tools' directory, which holds
    ``start`` (``start PORT DOMAIN``, printing ``<pid_key>=PID``) and ``stop.sh PORT``."""

    env: str
    start: str
    pid_key: str


PEERS = {
    "rosbridge": PeerTools("RWT_ROSBRIDGE_ROS2_DIR", "start_rosbridge_ros2.sh", "ROSBRIDGE_PID"),
    "rs": PeerTools("RWT_ROSBRIDGE_RS_DIR", "start.sh", "RS_PID"),
}
"""The peers: rosbridge_suite 2.1.0 on ROS 2 Kilted wheels, and rosbridge-server-rs
0.1.6 (Rust, a ROS 2 node on Jazzy wheels; its DDS meets the Kilted publisher)."""
PEER_ENV = PEERS["rosbridge"].env
PROFILE = ROOT / "tests" / "ros2" / "fastdds_loopback.xml"
LARGE_SHM_PROFILE = ROOT / "benchmarks" / "fastdds_large_shm.xml"
FASTDDS = {"loopback": PROFILE, "default": None, "large-shm": LARGE_SHM_PROFILE}
"""Fast DDS setups (``--fastdds``), the same for every process of a run: ``loopback``
loads ``PROFILE`` (UDP on 127.0.0.1 and shared memory, the tests' profile);
``default`` loads no XML: Fast DDS's builtin transports (shared memory and UDPv4),
what a robot gets out of the box; ``large-shm`` is ``loopback`` with a 4 MB
shared-memory segment instead of the default 512 KB, which a 921 KB image outgrows."""
PACED_HZ = 500
"""The paced String rate: below the ~600 msg/s rosbridge_suite 2.1.0 tops out at here."""
FAST_HZ = 5000
"""The fast paced String rate: what a bare rclpy subscriber still takes here, nearly whole."""
MID_HZ = 1000
"""The middle paced String rate, where CPU per delivery is compared with bare rclpy's."""
IMAGE_HZ = 30
MAX_RATE_P50_MS = 50
"""B21: rwt's p50 at full rate to 10 subscribers, ms at most: a reader that cannot keep
up loses old messages rather than waiting behind them (docs/ros2.md)."""
PROBE_EVERY_S = 0.05
DISCOVERY_S = 60.0
"""Bound on waiting for every subscriber's first probe."""
IDLE_S = 2.0
"""A subscriber that saw nothing for this long has seen all it will (a loss)."""
SETTLE_S = 10.0
"""Bound on waiting for a new bridge to go idle (under 10 % of a core) before a case."""
KINDS = ("rwt", "rosbridge", "rs", "rclpy")
BEFORE_ENV = "RWT_BEFORE_SRC"
"""The ``src`` folder of the ``before`` receiver's rwt (not one of ``KINDS``: named only)."""
LABELS = {
    "rwt": "rwt serve --ros2",
    "rosbridge": "rosbridge_suite 2.1.0",
    "rs": "rosbridge-server-rs 0.1.6",
    "rclpy": "bare rclpy subscriber",
    "before": "rwt serve --ros2, before",
}


@dataclass(frozen=True, slots=True)
class Case:
    """One measurement: message ``kind`` (``string``/``image``), rate (0 = as fast as rclpy can)."""

    kind: str
    hz: int
    subscribers: int

    @property
    def label(self) -> str:
        """``String max``, ``String 500 Hz``, ``Image 30 Hz``."""
        rate = "max" if not self.hz else f"{self.hz} Hz"
        return f"{'String 100 B' if self.kind == 'string' else 'Image 640x480'} {rate}"


CASES = [
    Case(kind, hz, subs)
    for kind, hz in (
        ("string", 0),
        ("string", FAST_HZ),
        ("string", MID_HZ),
        ("string", PACED_HZ),
        ("image", IMAGE_HZ),
    )
    for subs in (1, 10)
]


@dataclass(slots=True)
class Result:
    """The figures of one case on one receiver (see the module docstring)."""

    receiver: str
    case: str
    subscribers: int
    sent: int
    delivered: int
    msg_per_s: float
    loss: float
    p50_ms: float
    p99_ms: float
    cpu_us_per_delivery: float
    clients_cpu: float = 0.0
    """This process's CPU share while the WebSocket subscribers read (1.0 = one core)."""
    note: str = ""
    """What else happened (the server closed the publisher, peer_ros2)."""
    probes: int = 0
    """Probes the publisher sent before the timed messages (discovery)."""
    stages: dict[str, int] | None = None
    """rwt only: its per-stage counters of the case's topic (``stage_counts``)."""


PUB = r"""
import sys, time, threading, rclpy
from rclpy.qos import QoSProfile
kind, hz, seconds, topic = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
width, height = (int(x) for x in sys.argv[5:7]) if len(sys.argv) > 6 else (640, 480)
rclpy.init()
node = rclpy.create_node("bench_talker")
if kind == "string":
    from std_msgs.msg import String as Msg
    msg = Msg()
    def probe():
        m = Msg(); m.data = "probe"; return m
    def stamp(m):
        m.data = f"{time.time():.6f}".ljust(100, "x")
else:
    from sensor_msgs.msg import Image as Msg
    msg = Msg(); msg.height, msg.width, msg.encoding = height, width, "rgb8"
    msg.step = width * 3; msg.data = bytes(width * height * 3)
    def probe():
        m = Msg(); m.header.frame_id = "probe"; return m
    def stamp(m):
        now = time.time_ns()
        m.header.stamp.sec, m.header.stamp.nanosec = now // 1_000_000_000, now % 1_000_000_000
pub = node.create_publisher(Msg, topic, QoSProfile(depth=100))
go = threading.Event()
threading.Thread(target=lambda: (sys.stdin.readline(), go.set()), daemon=True).start()
print("ready", flush=True)
p = probe()
end = time.time() + 120
probes = 0
while not go.is_set() and time.time() < end:
    pub.publish(p)
    probes += 1
    time.sleep(0.05)
time.sleep(0.3)  # the last probes are through
print(time.time(), probes, flush=True)
sent, start = 0, time.monotonic()
while time.monotonic() - start < seconds:
    stamp(msg)
    while True:  # Fast DDS refuses a sample while its history is full of unsent ones
        try:
            pub.publish(msg)
            break
        except Exception:
            time.sleep(0.001)
    sent += 1
    if hz:
        delay = start + sent / hz - time.monotonic()
        if delay > 0:
            time.sleep(delay)
print(sent, flush=True)
sys.stdin.readline()
rclpy.shutdown()
"""

SUB = r"""
import sys, time, json, threading, rclpy
kind, topic = sys.argv[1], sys.argv[2]
rclpy.init()
node = rclpy.create_node("bench_counter")
lat, probed, state = [], threading.Event(), [0.0]
if kind == "string":
    from std_msgs.msg import String as Msg
    def on(m):
        now = time.time()
        if m.data == "probe":
            probed.set(); return
        lat.append(now - float(m.data[:17])); state[0] = now
else:
    from sensor_msgs.msg import Image as Msg
    def on(m):
        now = time.time()
        if m.header.frame_id == "probe":
            probed.set(); return
        lat.append(now - m.header.stamp.sec - m.header.stamp.nanosec / 1e9); state[0] = now
node.create_subscription(Msg, topic, on, 10)
ex = rclpy.executors.SingleThreadedExecutor(); ex.add_node(node)
threading.Thread(target=ex.spin, daemon=True).start()
print("ready", flush=True)
probed.wait(120)
print("probed", flush=True)
sys.stdin.readline()
print(json.dumps({"lat": lat, "last": state[0]}), flush=True)
ex.shutdown(); rclpy.shutdown()
"""


def rclpy_available() -> bool:
    """Whether rclpy (the ``ros2`` extra's ROS 2 wheels, or a sourced ROS 2) imports."""
    import importlib.util  # noqa: PLC0415

    return importlib.util.find_spec("rclpy") is not None


def ros_env(domain: int, fastdds: str = "loopback") -> dict[str, str]:
    """The ROS 2 environment of every process of a run: private domain, discovery on
    this host only, Fast DDS set up as ``fastdds`` (one of ``FASTDDS``) says."""
    env = {
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
        "ROS_DOMAIN_ID": str(domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "PYTHONUNBUFFERED": "1",
    }
    profile = FASTDDS[fastdds]
    if profile is not None:
        env["FASTDDS_DEFAULT_PROFILES_FILE"] = str(profile)
    return env


class Counter:
    """One ``websockets`` subscriber (``--client websockets``): counts timed messages and
    their latencies (s); each frame is assembled by the library, its stamp read as in
    ``ros2_client.stamp``, its content not checked."""

    def __init__(self) -> None:
        self.probed = asyncio.Event()
        self.latencies: list[float] = []
        self.last = 0.0

    async def run(self, url: str, topic: str, kind: str) -> None:
        """Subscribe to ``topic`` (of ``TYPES[kind]``) and read until cancelled."""
        import websockets  # noqa: PLC0415

        async with websockets.connect(url, max_size=None, compression=None) as ws:
            sub = {"op": "subscribe", "topic": topic, "type": TYPES[kind]}
            await ws.send(json.dumps(sub))
            while True:
                data = await ws.recv(decode=False)  # bytes: no UTF-8 decoding of 1 MB frames
                now = time.time()
                sent = stamp(kind, data)
                if sent is None:
                    self.probed.set()
                    continue
                self.latencies.append(now - sent)
                self.last = now


CLIENTS: dict[str, type[Counter | LeanCounter]] = {"lean": LeanCounter, "websockets": Counter}
"""The WebSocket subscribers ``--client`` picks from (module docstring)."""


def _percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


async def _line(proc: asyncio.subprocess.Process, within: float = DISCOVERY_S) -> str:
    assert proc.stdout is not None
    line = await asyncio.wait_for(proc.stdout.readline(), within)
    if not line:
        raise RuntimeError(f"a benchmark process ended early (status {await proc.wait()})")
    return line.decode().strip()


async def _say(proc: asyncio.subprocess.Process) -> None:
    assert proc.stdin is not None
    proc.stdin.write(b"go\n")
    await proc.stdin.drain()


@contextlib.asynccontextmanager
async def _child(code: str, *args: str, env: dict[str, str]) -> Any:
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-c",
        code,
        *args,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        env=env,
        limit=1 << 26,  # the bare subscriber's report: every latency, MBs at full rate
    )
    try:
        yield proc
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
        await proc.wait()


def _cpu(pid: int) -> float:
    return proc_stats(pid).cpu_s


async def _settle(pid: int) -> None:
    """Wait (at most ``SETTLE_S``) for the bridge to go idle: it loads types at start."""
    end = time.monotonic() + SETTLE_S
    while time.monotonic() < end:
        before = _cpu(pid)
        await asyncio.sleep(0.5)
        if _cpu(pid) - before < 0.05:
            return


async def _drain(
    counters: Sequence[Counter | LeanCounter], pid: int, sent_task: asyncio.Task[str]
) -> float:
    """Wait for the publisher to finish and the subscribers to go idle; CPU at the last delivery."""
    cpu = _cpu(pid)
    total = -1
    idle_since = time.monotonic()
    while True:
        await asyncio.sleep(0.1)
        now_total = sum(len(c.latencies) for c in counters)
        if now_total != total:
            total, idle_since, cpu = now_total, time.monotonic(), _cpu(pid)
        elif sent_task.done() and time.monotonic() - idle_since > IDLE_S:
            return cpu


def _result(
    receiver: str,
    case: Case,
    sent: int,
    start: float,
    latencies: list[float],
    last: float,
    cpu_s: float,
    subscribers: int,
) -> Result:
    delivered = len(latencies)
    elapsed = max(last - start, 1e-9)
    return Result(
        receiver=receiver,
        case=case.label,
        subscribers=subscribers,
        sent=sent,
        delivered=delivered,
        msg_per_s=delivered / elapsed if delivered else 0.0,
        loss=1 - delivered / max(sent * subscribers, 1),
        p50_ms=_percentile(latencies, 0.5) * 1e3,
        p99_ms=_percentile(latencies, 0.99) * 1e3,
        cpu_us_per_delivery=cpu_s / max(delivered, 1) * 1e6,
    )


async def _through_bridge(
    receiver: str,
    url: str,
    pid: int,
    case: Case,
    seconds: float,
    env: dict[str, str],
    client: str = "lean",
) -> Result:
    topic = f"/bench_{receiver}_{case.kind}_{case.hz}_{case.subscribers}"
    counters = [CLIENTS[client]() for _ in range(case.subscribers)]
    tasks = [asyncio.create_task(c.run(url, topic, case.kind)) for c in counters]
    try:
        async with _child(PUB, case.kind, str(case.hz), str(seconds), topic, env=env) as pub:
            await _line(pub)  # ready
            probed = asyncio.gather(*(c.probed.wait() for c in counters))
            await asyncio.wait_for(probed, DISCOVERY_S)
            await _settle(pid)
            await _say(pub)
            start_text, probes = (await _line(pub)).split()
            start = float(start_text)
            cpu0, own0 = _cpu(pid), time.process_time()
            sent_task = asyncio.create_task(_line(pub, seconds + DISCOVERY_S))
            cpu1 = await _drain(counters, pid, sent_task)
            own = (time.process_time() - own0) / max(time.time() - start, 1e-9)
            sent = int(await sent_task)
    finally:
        for task in tasks:
            task.cancel()
        ended = await asyncio.gather(*tasks, return_exceptions=True)
    for error in ended:  # a wrong delivery, or a subscriber the bridge dropped
        if isinstance(error, Exception):
            raise RuntimeError(f"a WebSocket subscriber failed: {error!r}") from error
    latencies = [x for c in counters for x in c.latencies]
    last = max(c.last for c in counters)
    result = _result(receiver, case, sent, start, latencies, last, cpu1 - cpu0, case.subscribers)
    result.clients_cpu = own
    result.probes = int(probes)
    return result


async def _bare(case: Case, seconds: float, env: dict[str, str]) -> Result:
    topic = f"/bench_rclpy_{case.kind}_{case.hz}"
    async with (
        _child(SUB, case.kind, topic, env=env) as sub,
        _child(PUB, case.kind, str(case.hz), str(seconds), topic, env=env) as pub,
    ):
        await _line(sub)  # ready
        await _line(pub)  # ready
        await _line(sub)  # probed
        await _say(pub)
        start = float((await _line(pub)).split()[0])
        cpu0 = _cpu(sub.pid)
        sent = int(await _line(pub, seconds + DISCOVERY_S))
        await asyncio.sleep(IDLE_S)
        cpu1 = _cpu(sub.pid)
        await _say(sub)
        report = json.loads(await _line(sub))
    return _result("rclpy", case, sent, start, report["lat"], report["last"], cpu1 - cpu0, 1)


def _start_rwt(domain: int, env: dict[str, str], log: IO[bytes], src: Path | None = None) -> Server:
    """``rwt serve --ros2 --no-tf`` (``start_server`` passes on ``os.environ``) on ``domain``
    in ``env`` (the run's: ``os.environ`` plus ``ros_env``), logging at INFO to ``log``;
    from the ``src`` folder ``src`` (None: this checkout's)."""
    saved = dict(os.environ)
    os.environ.clear()
    os.environ.update(env)
    try:
        extra = ["--ros2", "--no-tf", "--log-level", "info"]
        return start_server("rwt", extra=extra, src=src, stderr=log)
    finally:
        os.environ.clear()
        os.environ.update(saved)


STAGES = (
    "sent",
    "taken",
    "wakes",
    "max_batch",
    "handed",
    "refused",
    "expired",
    "published",
    "queued",
    "dropped",
    "expired_out",
    "written",
)
"""The per-stage counts of an rwt case, in order (``stage_counts``)."""


def stage_counts(log: str, result: Result) -> dict[str, int]:
    """rwt's per-stage counts of a case, from its log (docs/ros2.md, "Counters").

    ``sent``: what the publisher sent (probes included); ``taken`` ... ``published``:
    the link's ``event=ros2_counters`` line of the case's topic, plus ``batch_<bucket>``
    (wake-ups by samples taken); ``expired``: of those handed, dropped for their wait
    in the handoff; ``queued``, ``dropped``, ``expired_out``, ``written``: the
    subscribers' ``event=disconnect`` lines (topic messages queued, dropped, of those
    expired in the outbox, frames handed to the socket), summed over the subscribers.
    Absent lines (and fields: an older rwt's) count 0.
    """
    counts = dict.fromkeys(STAGES, 0)
    counts["sent"] = result.sent + result.probes
    for line in log.splitlines():
        fields = dict(re.findall(r"(\w+)=(\S+)", line))
        if fields.get("event") == "ros2_counters" and fields.get("topic", "").startswith("/bench_"):
            for key in ("taken", "wakes", "max_batch", "handed", "refused", "published"):
                counts[key] = int(fields[key])
            counts["expired"] = int(fields.get("expired", 0))
            for bucket in fields["batches"].split(","):
                name, _, n = bucket.partition(":")
                counts[f"batch_{name}"] = int(n)
        elif fields.get("event") == "disconnect":
            counts["queued"] += int(fields.get("topic_messages", 0))
            counts["dropped"] += int(fields.get("dropped", 0))
            counts["expired_out"] += int(fields.get("expired", 0))
            counts["written"] += int(fields.get("frames_sent", 0))
    return counts


def stage_table(results: list[Result]) -> str:
    """The Markdown table of rwt's per-stage counts (``stage_counts``) of ``results``."""
    rows = [r for r in results if r.stages]
    buckets = sorted(
        {k for r in rows for k in r.stages or {} if k.startswith("batch_")},
        key=lambda k: int(k[6:].split("-")[0].rstrip("+")),
    )
    head = [*STAGES, *buckets]
    lines = [
        "| case | subs | " + " | ".join(head) + " |",
        "|---|---:|" + "---:|" * len(head),
    ]
    for r in rows:
        stages = r.stages or {}
        cells = " | ".join(str(stages.get(k, 0)) for k in head)
        lines.append(f"| {r.case} | {r.subscribers} | {cells} |")
    return "\n".join(lines)


def _free_port() -> int:
    """A port nobody listens on now (the peer's scripts take a fixed port, not 0)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def _start_peer(receiver: str, tools: Path, port: int, domain: int) -> int:
    """Start a fresh peer bridge (``PEERS``) on ``port``; its WebSocket server's pid."""
    peer = PEERS[receiver]
    out = subprocess.run(
        [str(tools / peer.start), str(port), str(domain)],
        capture_output=True,
        text=True,
        check=True,
        timeout=180,
    ).stdout
    found = re.search(rf"{peer.pid_key}=(\d+)", out)
    if found is None:
        raise RuntimeError(f"{LABELS[receiver]} did not start: {out!r}")
    return int(found.group(1))


async def run_case(
    receiver: str,
    case: Case,
    seconds: float,
    domain: int,
    tools: Path | None = None,
    fastdds: str = "loopback",
    client: str = "lean",
) -> Result:
    """One ``case`` on ``receiver`` (``rwt``, ``rclpy``, or a peer of ``PEERS`` with ``tools``).

    Starts (and stops) the bridge; the ROS 2 processes use ``domain`` and the Fast DDS
    setup ``fastdds`` (``FASTDDS``; the peers' scripts set up their own environment);
    the WebSocket subscribers are ``CLIENTS[client]``.

    Raises:
        RuntimeError: a process did not start or ended early.
        TimeoutError: discovery took longer than ``DISCOVERY_S``.
    """
    env = {**os.environ, **ros_env(domain, fastdds)}
    if FASTDDS[fastdds] is None:  # none inherited either, under either name
        env.pop("FASTDDS_DEFAULT_PROFILES_FILE", None)
        env.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
    env["PYTHONPATH"] = rwt_pythonpath()
    if receiver == "rclpy":
        return await _bare(case, seconds, env)
    if receiver in ("rwt", "before"):
        src = Path(os.environ[BEFORE_ENV]) if receiver == "before" else None
        with tempfile.TemporaryFile() as log:
            with await asyncio.to_thread(_start_rwt, domain, env, log, src) as server:
                url = f"ws://127.0.0.1:{server.port}"
                pid = server.process.pid
                result = await _through_bridge(receiver, url, pid, case, seconds, env, client)
                await asyncio.sleep(0.5)  # the subscribers' disconnect lines
            log.seek(0)  # the server has stopped: its link logged its counters
            result.stages = stage_counts(log.read().decode("utf-8", "replace"), result)
        return result
    assert tools is not None

    async def measure(url: str, pid: int) -> Result:
        return await _through_bridge(receiver, url, pid, case, seconds, env, client)

    return await on_peer(receiver, tools, domain, measure)


async def on_peer(
    receiver: str, tools: Path, domain: int, measure: Callable[[str, int], Awaitable[Result]]
) -> Result:
    """Start a fresh peer of ``PEERS`` on a free port, ``measure(url, pid)``, then stop it."""
    port = _free_port()
    try:
        pid = await asyncio.to_thread(_start_peer, receiver, tools, port, domain)
        return await measure(f"ws://127.0.0.1:{port}", pid)
    finally:
        stop = [str(tools / "stop.sh"), str(port)]  # only what this start recorded
        await asyncio.to_thread(subprocess.run, stop, capture_output=True, check=False)


def peer_tools(receivers: list[str]) -> dict[str, Path]:
    """The tools' directory of each peer whose variable is set; the others leave
    ``receivers``, with a line saying why."""
    tools: dict[str, Path] = {}
    for name, peer in PEERS.items():
        if os.environ.get(peer.env):
            tools[name] = Path(os.environ[peer.env])
        elif name in receivers:
            print(f"{LABELS[name]} skipped: {peer.env} ({peer.start}'s dir) is unset")
            receivers.remove(name)
    return tools


def table(results: list[Result]) -> str:
    """The Markdown table of ``results``."""
    lines = [
        "| case | subs | receiver | sent | delivered msg/s | loss | p50 ms | p99 ms "
        "| CPU us/delivery | clients' CPU |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        lines.append(
            f"| {r.case} | {r.subscribers} | {LABELS[r.receiver]} | {r.sent} | {r.msg_per_s:,.0f} "
            f"| {r.loss:.1%} | {r.p50_ms:.1f} | {r.p99_ms:.1f} | {r.cpu_us_per_delivery:.0f} "
            f"| {'-' if r.receiver == 'rclpy' else f'{r.clients_cpu:.0%}'} |"
        )
    return "\n".join(lines)


def _met(ok: bool) -> str:
    return "met" if ok else "NOT met"


def medians(results: list[Result]) -> list[Result]:
    """One ``Result`` per case, subscribers and receiver: the rounds' medians, field by field."""
    groups: dict[tuple[str, int, str], list[Result]] = {}
    for r in results:
        groups.setdefault((r.case, r.subscribers, r.receiver), []).append(r)
    out = []
    for rs in groups.values():
        first = rs[0]
        out.append(
            Result(
                first.receiver,
                first.case,
                first.subscribers,
                round(statistics.median(r.sent for r in rs)),
                round(statistics.median(r.delivered for r in rs)),
                statistics.median(r.msg_per_s for r in rs),
                statistics.median(r.loss for r in rs),
                statistics.median(r.p50_ms for r in rs),
                statistics.median(r.p99_ms for r in rs),
                statistics.median(r.cpu_us_per_delivery for r in rs),
            )
        )
    return out


def verdicts(results: list[Result]) -> list[str]:
    """The targets of the ROS 2 bridge benchmark, each with the figures it was judged on
    (the rounds' medians, ``medians``)."""
    by = {(r.receiver, r.case, r.subscribers): r for r in medians(results)}
    out = []
    for case in CASES:
        name = f"{case.label} 1->{case.subscribers}"
        rwt = by.get(("rwt", case.label, case.subscribers))
        ref = by.get(("rosbridge", case.label, case.subscribers))
        bare = by.get(("rclpy", case.label, 1))
        if rwt and ref and not case.hz:
            ratio = rwt.msg_per_s / max(ref.msg_per_s, 1e-9)
            out.append(f"{name}: delivered {ratio:.1f}x rosbridge (>= 10x): {_met(ratio >= 10)}")
        if rwt and ref and case.hz and ref.loss == 0:
            out.append(f"{name}: rosbridge lossless, rwt loss {rwt.loss:.1%}: {_met(not rwt.loss)}")
        rust = by.get(("rs", case.label, case.subscribers))
        if rwt and rust:  # no target: the fastest peer users can pick, for comparison
            ratio = rwt.msg_per_s / max(rust.msg_per_s, 1e-9)
            out.append(
                f"{name}: delivered {ratio:.1f}x rosbridge-server-rs (loss {rust.loss:.1%}, "
                f"rwt {rwt.loss:.1%}; p99 {rust.p99_ms:.1f} ms, rwt {rwt.p99_ms:.1f} ms)"
            )
        if rwt and bare and case.subscribers == 1:
            ratio = rwt.cpu_us_per_delivery / max(bare.cpu_us_per_delivery, 1e-9)
            out.append(f"{name}: CPU/delivery {ratio:.1f}x bare rclpy (<= 2x): {_met(ratio <= 2)}")
        if rwt and bare and case.subscribers == 1 and case.hz == FAST_HZ:
            bound = 2 * bare.p99_ms + 2
            out.append(
                f"{name}: p99 {rwt.p99_ms:.1f} ms, bare rclpy {bare.p99_ms:.1f} ms "
                f"(<= 2x + 2 ms = {bound:.1f}): {_met(rwt.p99_ms <= bound)}"
            )
        if rwt and case.kind == "string" and not case.hz and case.subscribers > 1:
            p50 = rwt.p50_ms
            out.append(
                f"{name}: p50 {p50:.1f} ms (< {MAX_RATE_P50_MS} ms): {_met(p50 < MAX_RATE_P50_MS)}"
            )
        if rwt and case.kind == "image":
            p99 = rwt.p99_ms
            out.append(f"{name}: p99 {p99:.1f} ms (<= 20 ms): {_met(p99 <= 20)}")
    return out


async def run_all(
    receivers: list[str],
    cases: list[Case],
    seconds: float,
    domain: int,
    tools: dict[str, Path],
    fastdds: str = "loopback",
    client: str = "lean",
    rounds: int = 1,
) -> list[Result]:
    """Every case on every receiver, in that order (rclpy: the 1-subscriber cases only),
    ``rounds`` times over: interleaved, so a change of the machine's load spreads over all."""
    results = []
    for turn in range(rounds):
        for case in cases:
            for receiver in receivers:
                if receiver == "rclpy" and case.subscribers != 1:
                    continue
                label = f"{case.label} 1->{case.subscribers} {receiver}"
                print(f"round {turn + 1}/{rounds}: {label}...", file=sys.stderr, flush=True)
                where = tools.get(receiver)
                result = await run_case(receiver, case, seconds, domain, where, fastdds, client)
                results.append(result)
    return results


def _spread(values: list[float], fmt: str) -> str:
    """``median (min-max)`` of ``values`` with ``fmt``; the value alone for one."""
    middle = format(statistics.median(values), fmt)
    if len(values) == 1:
        return middle
    return f"{middle} ({format(min(values), fmt)}-{format(max(values), fmt)})"


def summary(results: list[Result]) -> str:
    """The Markdown table of ``results`` over rounds: medians, with (min-max) of the rounds."""
    groups: dict[tuple[str, int, str], list[Result]] = {}
    for r in results:
        groups.setdefault((r.case, r.subscribers, r.receiver), []).append(r)
    lines = [
        "| case | subs | receiver | rounds | delivered msg/s | loss | p50 ms | p99 ms "
        "| CPU us/delivery |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for (case, subs, receiver), rs in groups.items():
        lines.append(
            f"| {case} | {subs} | {LABELS[receiver]} | {len(rs)} "
            f"| {_spread([r.msg_per_s for r in rs], ',.0f')} "
            f"| {_spread([r.loss * 100 for r in rs], '.1f')} % "
            f"| {_spread([r.p50_ms for r in rs], '.1f')} "
            f"| {_spread([r.p99_ms for r in rs], '.1f')} "
            f"| {_spread([r.cpu_us_per_delivery for r in rs], '.0f')} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run every case; print the Markdown table and the verdicts (``--json``: every figure)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.ros2_bridge")
    parser.add_argument("--seconds", type=float, default=5.0, help="timed publishing per case")
    parser.add_argument(
        "--receivers",
        default=",".join(KINDS),
        help=f"comma-separated: rwt,rosbridge,rs,rclpy, and before (rwt from ${BEFORE_ENV})",
    )
    parser.add_argument(
        "--subscribers", type=int, help="only the cases with this many subscribers (1 or 10)"
    )
    parser.add_argument(
        "--cases",
        help="only the cases whose label contains one of these, comma-separated "
        "(Image; 'String 100 B 5000 Hz,String 100 B max')",
    )
    parser.add_argument("--domain", type=int, default=130 + os.getpid() % 10, help="ROS_DOMAIN_ID")
    parser.add_argument(
        "--fastdds",
        choices=list(FASTDDS),
        default="loopback",
        help="Fast DDS setup of every process: loopback (the tests' XML), default (no XML), "
        "large-shm (loopback with a 4 MB shared-memory segment)",
    )
    parser.add_argument(
        "--client",
        choices=list(CLIENTS),
        default="lean",
        help="the WebSocket subscribers: lean (frames walked as they arrive, each image "
        "checked in place; benchmarks/ros2_client.py) or websockets (the library, unchecked)",
    )
    parser.add_argument(
        "--rounds", type=int, default=1, help="run every case this often, interleaved"
    )
    parser.add_argument("--json", type=Path, help="write the results here")
    args = parser.parse_args(argv)
    if not rclpy_available():
        print('skipped: rclpy is not importable (pip install "rwt-rosbridge[ros2]")')
        return 0
    receivers = [r for r in args.receivers.split(",") if r]
    tools = peer_tools(receivers)
    wanted = [w for w in (args.cases or "").split(",") if w]
    cases = [
        c
        for c in CASES
        if (not wanted or any(w in f"{c.label} 1->{c.subscribers}" for w in wanted))
        and args.subscribers in (None, c.subscribers)
    ]
    if "before" in receivers and not os.environ.get(BEFORE_ENV):
        parser.error(f"--receivers before needs {BEFORE_ENV} (the src folder of the code before)")
    results = asyncio.run(
        run_all(
            receivers,
            cases,
            args.seconds,
            args.domain,
            tools,
            args.fastdds,
            args.client,
            max(args.rounds, 1),
        )
    )
    print(table(results))
    print()
    if args.rounds > 1:
        print(summary(results))
        print()
    if any(r.stages for r in results):
        print(stage_table(results))
        print()
    for line in verdicts(results):
        print(f"- {line}")
    if args.json:
        args.json.write_text(json.dumps([asdict(r) for r in results], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
