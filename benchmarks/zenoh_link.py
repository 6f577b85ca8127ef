"""Z3 at the link: two processes, each a ``Graph`` with the Zenoh link, against bare Zenoh.

The end-to-end Z3 of ``scaleout`` goes through two rosbridge servers (JSON and
WebSocket in Python at both edges); this one measures the link alone, as an
embedding program uses it (``open_zenoh_link``, docs/zenoh.md):

- process A: a graph, its link, a publisher; after discovery it publishes
  ``count`` messages into its graph as fast as it can (the link's tap encodes
  each to CDR and puts it on Zenoh);
- process B: a graph, its link, a subscription counting what reaches it (the
  link decodes each sample and publishes it in B's graph).

Two references run in the same round: a bare Zenoh publisher and subscriber in two
processes carrying payloads of the same CDR sizes, callbacks that only count; and
real rclpy (PyPI's ROS 2 Kilted wheels), a publisher node and a subscription node in
two processes over Fast DDS on loopback, with the same message types, reliable and
keep all (so nothing is lost), the subscription taking each message as a Python
object as a ROS 2 program does: what a user would otherwise pick to move ROS
messages between two Python processes.

Every process of both pairs keeps 64 MiB of freed heap for the next message
(``rwt_transports.process.allocator.tune_allocator``), as ``rwt serve`` does by default
(``--heap-keep``): with glibc's defaults each 1 MB buffer (the CDR, Zenoh's copy,
the decoded bytes) is mapped afresh, and a 1 MB message cost each side about
500 page faults and four times the CPU. The rate is messages
delivered per second, from A's first publish to B's last delivery (wall clock,
one machine). Each side is ``python -m benchmarks.zenoh_link ROLE ...``; the
parent (``run_pair``) starts B, then A, and tells A when B got a probe (Zenoh's
discovery is eventual), so that the timed messages all have a route.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from .servers import rwt_pythonpath

REPO = Path(__file__).resolve().parents[1]
TIMEOUT_S = 120.0
HEAP_KEEP = 64 * 1024 * 1024
"""Bytes of freed heap each process keeps, ``rwt serve``'s default ``--heap-keep``."""
IDLE_S = 3.0
"""A receiver that saw nothing for this long has seen all it will (a loss)."""

SIZES = {
    100: ("std_msgs/msg/String", "100 B String"),
    1_000_000: ("sensor_msgs/msg/Image", "1 MB Image"),
}


def message(size: int, marker: str = "") -> dict[str, object]:
    """The timed message of ``size`` payload bytes (``marker`` tells a probe apart)."""
    if size == 100:
        return {"data": (marker or "z").ljust(100, "z")}
    side = int(size**0.5)
    return {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": marker},
        "height": side,
        "width": side,
        "encoding": "mono8",
        "is_bigendian": 0,
        "step": side,
        "data": bytes(side * side),
    }


def cdr_size(size: int) -> int:
    """The CDR payload length of the timed message, what the bare pair carries."""
    from rwt_graph.types.registry import TypeRegistry  # noqa: PLC0415
    from rwt_zenoh.payload import encode_sample  # noqa: PLC0415

    return len(encode_sample(TypeRegistry(), SIZES[size][0], message(size)))


def _options(listen: str | None, connect: str | None) -> Any:
    from rwt_zenoh.config import ZenohOptions  # noqa: PLC0415

    return ZenohOptions(
        listen=() if listen is None else (listen,),
        connect=() if connect is None else (connect,),
        domain_id=0,
    )


def _probe(msg: dict[str, object]) -> bool:
    data = msg.get("data")
    if isinstance(data, str):
        return data.startswith("probe")
    header = msg.get("header")
    return isinstance(header, dict) and header.get("frame_id") == "probe"


async def _receiver(endpoint: str, size: int, count: int) -> None:
    """B: count the timed messages reaching a graph subscription; print last time and count."""
    from rwt_graph.graph import Graph  # noqa: PLC0415
    from rwt_zenoh.link import open_zenoh_link  # noqa: PLC0415

    graph = Graph()
    got: list[float] = [0, 0.0, 0.0, 0.0]  # count, last wall time, CPU at first and last

    probed = asyncio.Event()

    def on_message(msg: dict[str, object]) -> None:
        if _probe(msg):
            probed.set()
            return
        if not got[0]:
            got[2] = time.process_time()
        got[0] += 1
        got[1] = time.time()
        got[3] = time.process_time()

    async with open_zenoh_link(graph, _options(endpoint, None)):
        graph.create_subscription("/tp", on_message, SIZES[size][0], node="/counter")
        print("ready", flush=True)
        await asyncio.wait_for(probed.wait(), TIMEOUT_S)
        print("flowing", flush=True)
        last = -1.0
        while got[0] < count:
            await asyncio.sleep(IDLE_S)
            if got[0] == last:
                break
            last = got[0]
        cpu_us = (got[3] - got[2]) / max(got[0] - 1, 1) * 1e6  # all threads of B
        print(got[1], int(got[0]), cpu_us, flush=True)


async def _sender(endpoint: str, size: int, count: int) -> None:
    """A: publish probes until told to go on stdin, then ``count`` messages; print the start."""
    from rwt_graph.graph import Graph  # noqa: PLC0415
    from rwt_zenoh.link import open_zenoh_link  # noqa: PLC0415

    graph = Graph()
    go = threading.Event()

    def wait_for_go() -> None:
        sys.stdin.readline()
        go.set()

    threading.Thread(target=wait_for_go, daemon=True).start()
    async with open_zenoh_link(graph, _options(None, endpoint)):
        pub = graph.create_publisher("/tp", SIZES[size][0], node="/talker")
        probe = message(size, "probe")
        deadline = time.monotonic() + TIMEOUT_S
        while not go.is_set() and time.monotonic() < deadline:
            pub.publish(probe)
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.2)  # the last probes are through
        msg = message(size)
        print(time.time(), flush=True)
        cpu = time.process_time()
        for number in range(count):
            pub.publish(msg)
            if number % 64 == 63:
                await asyncio.sleep(0)  # the link's other work (tokens, sweeps) runs
        print((time.process_time() - cpu) / count * 1e6, flush=True)  # all threads of A
        sys.stdin.readline()  # until the parent has B's figures


BARE_SUB = f"""
import sys, time, threading, zenoh
from rwt_transports.process.allocator import tune_allocator
tune_allocator({HEAP_KEEP})
ep, count = sys.argv[1], int(sys.argv[2])
c = zenoh.Config()
c.insert_json5("mode", '"peer"'); c.insert_json5("scouting/multicast/enabled", "false")
c.insert_json5("listen/endpoints", f'["{{ep}}"]')
s = zenoh.open(c)
got = [0, 0.0]; probed = threading.Event()
cpu = [0.0, 0.0]
def on(sample):
    if sample.payload.to_bytes()[:5] == b"probe":
        probed.set()
        return
    if not got[0]:
        cpu[0] = time.process_time()
    got[0] += 1
    got[1] = time.time()
    cpu[1] = time.process_time()
sub = s.declare_subscriber("bench/tp", on)
print("ready", flush=True)
probed.wait(120)
print("flowing", flush=True)
last = -1
while got[0] < count:
    time.sleep(3)
    if got[0] == last:
        break
    last = got[0]
print(got[1], got[0], (cpu[1] - cpu[0]) / max(got[0] - 1, 1) * 1e6, flush=True)
s.close()
"""

BARE_PUB = f"""
import sys, time, threading, zenoh
from rwt_transports.process.allocator import tune_allocator
tune_allocator({HEAP_KEEP})
ep, count, size = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
c = zenoh.Config()
c.insert_json5("mode", '"peer"'); c.insert_json5("scouting/multicast/enabled", "false")
c.insert_json5("connect/endpoints", f'["{{ep}}"]')
s = zenoh.open(c)
go = threading.Event()
threading.Thread(target=lambda: (sys.stdin.readline(), go.set()), daemon=True).start()
pub = s.declare_publisher("bench/tp")
deadline = time.time() + 120
while not go.is_set() and time.time() < deadline:
    pub.put(b"probe".ljust(size, b"z"))
    time.sleep(0.05)
time.sleep(0.2)
payload = b"z" * size
print(time.time(), flush=True)
cpu = time.process_time()
for _ in range(count):
    pub.put(payload)
print((time.process_time() - cpu) / count * 1e6, flush=True)
sys.stdin.readline()
s.close()
"""


RCLPY_COMMON = f"""
import sys, time, threading, rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy, DurabilityPolicy
from rwt_transports.process.allocator import tune_allocator
tune_allocator({HEAP_KEEP})
count, size = int(sys.argv[1]), int(sys.argv[2])
if size == 100:
    from std_msgs.msg import String as Msg
    def make(marker):
        m = Msg(); m.data = (marker or "z").ljust(100, "z"); return m
    def is_probe(m):
        return m.data.startswith("probe")
else:
    from sensor_msgs.msg import Image as Msg
    side = int(size ** 0.5)
    def make(marker):
        m = Msg(); m.header.frame_id = marker; m.height = m.width = m.step = side
        m.encoding = "mono8"; m.data = bytes(side * side); return m
    def is_probe(m):
        return m.header.frame_id == "probe"
qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_ALL,
                 durability=DurabilityPolicy.VOLATILE)
rclpy.init()
"""

RCLPY_SUB = (
    RCLPY_COMMON
    + """
node = rclpy.create_node("bench_counter")
got = [0, 0.0]; cpu = [0.0, 0.0]; probed = threading.Event()
def on(m):
    if is_probe(m):
        probed.set(); return
    if not got[0]:
        cpu[0] = time.process_time()
    got[0] += 1; got[1] = time.time(); cpu[1] = time.process_time()
node.create_subscription(Msg, "/tp", on, qos)
executor = rclpy.executors.SingleThreadedExecutor(); executor.add_node(node)
threading.Thread(target=executor.spin, daemon=True).start()
print("ready", flush=True)
probed.wait(120)
print("flowing", flush=True)
last = -1
while got[0] < count:
    time.sleep(3)
    if got[0] == last:
        break
    last = got[0]
print(got[1], got[0], (cpu[1] - cpu[0]) / max(got[0] - 1, 1) * 1e6, flush=True)
executor.shutdown(); rclpy.shutdown()
"""
)

RCLPY_PUB = (
    RCLPY_COMMON
    + """
node = rclpy.create_node("bench_talker")
pub = node.create_publisher(Msg, "/tp", qos)
go = threading.Event()
threading.Thread(target=lambda: (sys.stdin.readline(), go.set()), daemon=True).start()
probe = make("probe")
deadline = time.time() + 120
while not go.is_set() and time.time() < deadline:
    pub.publish(probe)
    time.sleep(0.05)
time.sleep(0.2)
msg = make("")
def send(m):
    # A reliable KEEP_ALL writer whose history is full waits Fast DDS's
    # max_blocking_time (100 ms), then refuses ("cannot publish data"): the reader
    # is behind. A program keeping every message publishes it again.
    while True:
        try:
            pub.publish(m)
            return
        except Exception as exc:
            if "cannot publish data" not in str(exc):
                raise
print(time.time(), flush=True)
cpu = time.process_time()
for _ in range(count):
    send(msg)
print((time.process_time() - cpu) / count * 1e6, flush=True)
sys.stdin.readline()
rclpy.shutdown()
"""
)


def rclpy_available() -> bool:
    """Whether rclpy (the ``ros2`` extra's ROS 2 wheels, or a sourced ROS 2) imports."""
    import importlib.util  # noqa: PLC0415

    return importlib.util.find_spec("rclpy") is not None


def _env() -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": rwt_pythonpath()}
    # rclpy pairs: a private domain, discovery on this machine only
    env.setdefault("ROS_DOMAIN_ID", str(100 + os.getpid() % 100))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    return env


async def _line(proc: asyncio.subprocess.Process) -> str:
    assert proc.stdout is not None
    line = await asyncio.wait_for(proc.stdout.readline(), TIMEOUT_S)
    if not line:
        raise RuntimeError(f"a benchmark process ended early (status {await proc.wait()})")
    return line.decode().strip()


def _cpu_ns(pid: int) -> int:
    """CPU time of every thread of process ``pid`` so far, ns (``/proc/<pid>/task/*/schedstat``)."""
    total = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError, ValueError, IndexError):
            total += int((task / "schedstat").read_text().split()[0])
    return total


async def _watch_cpu(pid: int, into: list[tuple[float, int]]) -> None:
    """Append (wall time, ``_cpu_ns``) of ``pid`` every 5 ms until cancelled."""
    while True:
        with contextlib.suppress(OSError):
            into.append((time.time(), _cpu_ns(pid)))
        await asyncio.sleep(0.005)


def _cpu_between(samples: list[tuple[float, int]], start: float, end: float) -> float:
    """CPU ns spent between the wall times ``start`` and ``end`` (nearest samples after each)."""

    def at(moment: float) -> int:
        return next((ns for wall, ns in samples if wall >= moment), samples[-1][1])

    return float(at(end) - at(start)) if samples else 0.0


async def run_pair(kind: str, size: int, count: int, endpoint: str) -> dict[str, float]:
    """One transfer of ``count`` messages A->B.

    ``kind``: ``link`` (two graphs with their links), ``bare`` (plain Zenoh) or
    ``rclpy`` (two rclpy nodes over Fast DDS; ``endpoint`` unused).

    Returns:
        ``msg_per_s``, ``mb_per_s`` (of the CDR payload), ``got``, ``sent``,
        ``sender_cpu_us`` and ``receiver_cpu_us``: each process's CPU time (all
        its threads) per message while it sent or received. A's is read by this
        process from /proc, from A's first publish to B's last delivery: the
        link's outbox thread still puts after A's publish calls have returned.
    """
    payload = cdr_size(size)
    env = _env()
    if kind == "link":
        role = [sys.executable, "-m", "benchmarks.zenoh_link"]
        sub_cmd = [*role, "receive", endpoint, str(size), str(count)]
        pub_cmd = [*role, "send", endpoint, str(size), str(count)]
    elif kind == "rclpy":
        sub_cmd = [sys.executable, "-c", RCLPY_SUB, str(count), str(size)]
        pub_cmd = [sys.executable, "-c", RCLPY_PUB, str(count), str(size)]
    else:
        sub_cmd = [sys.executable, "-c", BARE_SUB, endpoint, str(count)]
        pub_cmd = [sys.executable, "-c", BARE_PUB, endpoint, str(count), str(payload)]
    pipes: dict[str, Any] = {"stdout": subprocess.PIPE, "stdin": subprocess.PIPE, "env": env}
    procs: list[asyncio.subprocess.Process] = []
    try:
        sub = await asyncio.create_subprocess_exec(*sub_cmd, **pipes)
        procs.append(sub)
        await _line(sub)  # ready
        pub = await asyncio.create_subprocess_exec(*pub_cmd, **pipes)
        procs.append(pub)
        await _line(sub)  # flowing: a probe came through
        assert pub.stdin is not None
        samples: list[tuple[float, int]] = []
        watch = asyncio.create_task(_watch_cpu(pub.pid, samples))
        pub.stdin.write(b"go\n")
        await pub.stdin.drain()
        start = float(await _line(pub))
        await _line(pub)  # A's own figure: its publish calls only
        end, got, receiver_cpu = (await _line(sub)).split()
        watch.cancel()
        sender_cpu = _cpu_between(samples, start, float(end)) / 1e3 / count
        elapsed = max(float(end) - start, 1e-9)
        rate = int(got) / elapsed
        return {
            "msg_per_s": rate,
            "mb_per_s": rate * payload / 1e6,
            "got": int(got),
            "sent": count,
            "sender_cpu_us": sender_cpu,
            "receiver_cpu_us": float(receiver_cpu),
        }
    finally:
        for proc in procs:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()


def main(argv: list[str]) -> int:
    """``receive|send ENDPOINT SIZE COUNT``: one side of a link transfer (for ``run_pair``)."""
    from rwt_transports.process.allocator import tune_allocator  # noqa: PLC0415

    tune_allocator(HEAP_KEEP)
    role, endpoint, size, count = argv[0], argv[1], int(argv[2]), int(argv[3])
    side = _receiver if role == "receive" else _sender
    asyncio.run(side(endpoint, size, count))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
