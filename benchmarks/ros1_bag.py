"""B22: record and play next to the real ROS 1 ``rosbag``, on Debian's ROS 1.

``python -m benchmarks rosbag [--runs 3] [--smoke]`` (or ``python -m
benchmarks.ros1_bag``). Needs ``roscore``, ``rosbag`` and rospy (Debian:
``ros-core``, ``python3-rospy``, ``python3-std-msgs``, ``python3-sensor-msgs``);
without them it says so and exits 0.

Record, one live stream at a time, into a ROS 1 bag:

- rwt: ``rwt serve --dialect ros1 --record BAG --record-format ros1``; the
  publisher is one raw-socket WebSocket client in this process (the load
  generator's frames, ``benchmarks/loadgen/wire.py``): JSON ``publish`` ops
  written with blocking ``sendall`` as fast as the server takes them, or paced.
- ROS 1: ``rosbag record -O BAG TOPIC`` (its defaults); the publisher is a
  rospy node (``benchmarks/ros1_nodes.py``, ``queue_size=None``: each publish
  is written to the socket, nothing is dropped on its side).

Streams: 100 B ``std_msgs/String`` as fast as each publisher goes, and a
640x480 rgb8 ``sensor_msgs/Image`` at 30 Hz (CBOR from the WebSocket client,
its data a byte string). Each publisher waits until the recorder listens (rwt:
0.5 s after ``advertise``, more than the recorder's 0.2 s look for new topics;
rospy: a connection). The window runs from the first publish to the last
publish or the last message's receive time in the bag, whichever is later, so
a recorder that lags is charged for it. Figures: sustained rate = messages in
the bag / window; drops = published - in the bag; the recorder's CPU (the
process and its children, /proc) from the first publish until it is idle
again (all it received handled), as a share of a core over the window and
per recorded message. Target: no drops, rate >= 1.0x rosbag's.

Play the same ROS 1 bag of 10,000 100 B strings (1 kHz, written once by
rosbags) at full speed:

- rwt: ``rwt play BAG --rate 1e6 --start-paused`` to one raw-socket WebSocket
  client that subscribes, calls ``/rwt/player/resume`` and checks every frame
  byte for byte.
- ROS 1: ``rosbag play --immediate --queue 10000 --wait-for-subscribers BAG``
  to a rospy subscriber that checks every message.

Figures: messages delivered / (last arrival - first arrival), delivered count,
the player's CPU between the first and the last arrival. Target: >= 0.5x.

Rounds run interleaved (rwt, ROS 1, then ROS 1, rwt...), medians reported.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import xmlrpc.client
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cbor2
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.typesys import Stores, get_typestore

from .loadgen.engine import BARRIER
from .loadgen.wire import FrameReader, client_frame, connect
from .msgs import advertise, publish_json, subscribe
from .ros1_nodes import IMAGE_HEIGHT, IMAGE_WIDTH, string_data, tree_cpu_s
from .servers import ROOT, ROS1_PROBES, ROS1_PYTHON, imports_ok

__all__ = ["Measure", "missing", "run", "table", "verdict"]

ROS_PYTHON = ROS1_PYTHON
NODES = Path(__file__).with_name("ros1_nodes.py")
RESULTS = Path(__file__).parent / "results" / "ros1_bag.json"
TOPIC = "/b22"
IMAGE_HZ = 30.0
PLAY_COUNT = 10_000
PLAY_GAP_NS = 1_000_000  # 1 kHz in the bag
_IDLE_CPU_S = 0.02
"""A recorder using less CPU than this in 0.25 s has handled all it received."""
_LIMIT_S = 120.0


def missing() -> str | None:
    """Why B22 cannot run here (a tool or module absent), or None."""
    for tool in ("roscore", "rosbag"):
        if shutil.which(tool) is None:
            return f"{tool} is not installed (Debian: ros-core, python3-rosbag)"
    if not imports_ok(ROS_PYTHON, ROS1_PROBES["rospy"]):
        return f"{ROS_PYTHON} cannot import rospy, std_msgs and sensor_msgs (Debian: python3-rospy)"
    return None


@dataclass
class Measure:
    """One side's figures for one round of one stream."""

    sent: int
    in_bag: int
    window_s: float
    cpu_s: float
    client_cpu_s: float | None = None
    """This process's CPU as the WebSocket client (rwt play), to show it is not the limit."""

    @property
    def rate(self) -> float:
        """Messages in the bag (or delivered) per second of the window."""
        return self.in_bag / self.window_s if self.window_s > 0 else 0.0

    @property
    def drops(self) -> int:
        """Published but not in the bag (or not delivered)."""
        return self.sent - self.in_bag


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@contextlib.contextmanager
def roscore(tmp: Path) -> Iterator[dict[str, str]]:
    """A private ``roscore`` on a free port; yields the environment that reaches it.

    Raises:
        RuntimeError: the master did not answer within 30 s.
    """
    port = _free_port()
    env = dict(os.environ)
    env.update(
        ROS_MASTER_URI=f"http://127.0.0.1:{port}",
        ROS_HOME=str(tmp / "ros_home"),
        ROS_LOG_DIR=str(tmp / "ros_log"),
        ROS_IP="127.0.0.1",
    )
    core = subprocess.Popen(
        ["roscore", "-p", str(port)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 30.0
        while not _master_answers(env["ROS_MASTER_URI"]):
            if time.monotonic() > deadline or core.poll() is not None:
                raise RuntimeError("roscore did not start")
            time.sleep(0.1)
        yield env
    finally:
        _stop(core, signal.SIGINT)


def _master_answers(uri: str) -> bool:
    with xmlrpc.client.ServerProxy(uri) as master, contextlib.suppress(OSError):
        return bool(master.getSystemState("/b22")[0] == 1)  # type: ignore[index]
    return False


def _stop(process: subprocess.Popen[bytes], sig: int, limit_s: float = 60.0) -> None:
    """Signal ``process``'s group and wait for the whole tree; SIGKILL after ``limit_s``.

    ``rosbag`` exits on SIGINT while its C++ child still closes the bag, so
    the children are waited for too.
    """
    tree = _descendants(process.pid)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, sig)
    deadline = time.monotonic() + limit_s
    while any(_running(pid) for pid in [process.pid, *tree]) or process.poll() is None:
        if time.monotonic() > deadline:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)
            process.wait()
            break
        time.sleep(0.05)
    if process.stdout is not None:
        process.stdout.close()


def _descendants(pid: int) -> list[int]:
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        with contextlib.suppress(OSError, ValueError):
            if entry.name.isdigit():
                ppid = int((entry / "stat").read_text("ascii").rpartition(")")[2].split()[1])
                children.setdefault(ppid, []).append(int(entry.name))
    found, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def _running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text("ascii").rpartition(")")[2].split()[0]
    except OSError:
        return False
    return state != "Z"


def _until_idle(pid: int) -> float:
    """Wait until ``pid``'s tree is idle (all it received is handled); its CPU seconds then."""
    deadline = time.monotonic() + _LIMIT_S
    before = tree_cpu_s(pid)
    while time.monotonic() < deadline:
        time.sleep(0.25)
        now = tree_cpu_s(pid)
        if now - before < _IDLE_CPU_S:
            return now
        before = now
    raise RuntimeError("the recorder was still busy after 120 s")


def _bag_figures(bag: Path) -> tuple[int, float]:
    """Messages in a ROS 1 bag and its last receive time (seconds since the epoch)."""
    with AnyReader([bag]) as reader:
        return reader.message_count, reader.end_time / 1e9


def _measure(sent: int, first: float, last: float, cpu_s: float, bag: Path) -> Measure:
    count, end = _bag_figures(bag)
    return Measure(sent, count, max(last, end) - first, cpu_s)


# --- record: rwt ----------------------------------------------------------


def _start_rwt(command: list[str]) -> tuple[subprocess.Popen[bytes], int]:
    """Start ``python -m rwt COMMAND...`` and read its ``listening on`` line."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), str(ROOT)])
    process = subprocess.Popen(
        [sys.executable, "-m", "rwt", *command, "--port", "0"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        start_new_session=True,
    )
    line = process.stdout.readline().decode().strip()  # type: ignore[union-attr]
    if not line.startswith("listening on ws://"):
        _stop(process, signal.SIGKILL)
        raise RuntimeError(f"rwt {command[0]} did not start: {line!r}")
    return process, int(line.rsplit(":", 1)[1])


def _client(port: int, setup: bytes) -> socket.socket:
    """A raw WebSocket client that sent the ``setup`` op and got the barrier's answer.

    Raises:
        ConnectionError: the server closed the connection first.
    """
    sock, rest = connect(port)
    sock.sendall(client_frame(setup))
    _barrier(sock, rest)
    return sock


def _barrier(sock: socket.socket, rest: bytes = b"") -> None:
    """Send the barrier call and read until its answer: the server has handled every
    frame sent before it (one connection's frames are handled in order).

    Raises:
        ConnectionError: the server closed the connection first.
    """
    sock.sendall(client_frame(BARRIER))
    reader = FrameReader()
    frames = reader.feed(rest)
    while not any(b'"barrier"' in payload for _, payload in frames):
        chunk = sock.recv(65536)
        if not chunk:
            sock.close()
            raise ConnectionError("the server closed the connection before the barrier")
        frames = reader.feed(chunk)


def _string_frames() -> list[bytes]:
    """1,000 frames of 100 B strings, batched into writes of about 64 KiB."""
    frames = [
        client_frame(publish_json(TOPIC, b'{"data":"' + string_data(i).encode() + b'"}'))
        for i in range(1000)
    ]
    per = 65536 // len(frames[0])
    return [b"".join(frames[i : i + per]) for i in range(0, len(frames), per)]


def _image_frame(seq: int) -> bytes:
    size = IMAGE_WIDTH * IMAGE_HEIGHT * 3
    data = (bytes(range(256)) * (size // 256 + 1))[:size]
    now = time.time()
    msg = {
        "header": {
            "seq": seq,
            "stamp": {"secs": int(now), "nsecs": int(now % 1 * 1e9)},
            "frame_id": "camera",
        },
        "height": IMAGE_HEIGHT,
        "width": IMAGE_WIDTH,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": IMAGE_WIDTH * 3,
        "data": data,
    }
    return client_frame(cbor2.dumps({"op": "publish", "topic": TOPIC, "msg": msg}), binary=True)


def _publish_rwt(sock: socket.socket, kind: str, seconds: float) -> tuple[int, float, float]:
    """Publish the stream; the count and the wall times of the first and last publish."""
    first = time.time()
    sent = 0
    if kind == "string":
        batches = _string_frames()
        sizes = [batch.count(b'"op":"publish"') for batch in batches]
        index = 0
        while time.time() < first + seconds:
            sock.sendall(batches[index])
            sent += sizes[index]
            index = (index + 1) % len(batches)
    else:
        for i in range(max(1, round(seconds * IMAGE_HZ))):
            delay = first + i / IMAGE_HZ - time.time()
            if delay > 0:
                time.sleep(delay)
            sock.sendall(_image_frame(i))
            sent += 1
    return sent, first, time.time()


def record_rwt(tmp: Path, kind: str, seconds: float) -> Measure:
    """``rwt serve --record`` of one stream (``kind``: ``string`` or ``image``)."""
    bag = tmp / "rwt.bag"
    recording = ["--record", str(bag), "--record-format", "ros1", "--record-topics", TOPIC]
    process, port = _start_rwt(["serve", "--dialect", "ros1", *recording, "--log-level", "warning"])
    try:
        type_name = "std_msgs/String" if kind == "string" else "sensor_msgs/Image"
        with _client(port, advertise(TOPIC, type_name)) as sock:
            time.sleep(0.5)  # the recorder looks for new topics every 0.2 s
            cpu0 = tree_cpu_s(process.pid)
            sent, first, last = _publish_rwt(sock, kind, seconds)
            # every publish handled before the recorder is stopped: on a loaded
            # machine an idle-looking second is no proof that the socket was drained
            _barrier(sock)
            cpu1 = _until_idle(process.pid)
    finally:
        _stop(process, signal.SIGTERM)
    return _measure(sent, first, last, cpu1 - cpu0, bag)


# --- record: ROS 1 ------------------------------------------------------------


def record_rosbag(tmp: Path, env: dict[str, str], kind: str, seconds: float) -> Measure:
    """Real ``rosbag record`` of one stream from a rospy publisher."""
    bag = tmp / "rosbag.bag"
    recorder = subprocess.Popen(
        ["rosbag", "record", "-O", str(bag), TOPIC],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        args = ["pub-string", str(seconds), TOPIC]
        if kind == "image":
            args = ["pub-image", str(seconds), TOPIC, str(IMAGE_HZ)]
        with subprocess.Popen(
            [ROS_PYTHON, str(NODES), *args],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
        ) as publisher:
            assert publisher.stdout is not None
            if publisher.stdout.readline().strip() != b"go":
                raise RuntimeError("the rospy publisher did not connect")
            cpu0 = tree_cpu_s(recorder.pid)
            result = json.loads(publisher.stdout.readline())
        cpu1 = _until_idle(recorder.pid)
    finally:
        _stop(recorder, signal.SIGINT)
    return _measure(result["sent"], result["first"], result["last"], cpu1 - cpu0, bag)


# --- play ---------------------------------------------------------------------


def write_play_bag(path: Path, count: int) -> None:
    """The ROS 1 bag both players play: ``count`` strings ``string_data(i)`` at 1 kHz."""
    store = get_typestore(Stores.ROS1_NOETIC)
    cls = store.types["std_msgs/msg/String"]
    with Ros1Writer(path) as writer:
        conn = writer.add_connection(TOPIC, "std_msgs/msg/String", typestore=store)
        for i in range(count):
            raw = store.serialize_ros1(cls(data=string_data(i)), "std_msgs/msg/String")
            writer.write(conn, 1_700_000_000 * 10**9 + i * PLAY_GAP_NS, raw)


def play_rwt(bag: Path, count: int) -> Measure:
    """``rwt play`` to one raw WebSocket client that checks every frame."""
    process, port = _start_rwt(["play", str(bag), "--rate", "1e6", "--start-paused"])
    expected = [
        publish_json(TOPIC, b'{"data":"' + string_data(i).encode() + b'"}') for i in range(count)
    ]
    try:
        with _client(port, subscribe(TOPIC, "std_msgs/String")) as sock:
            reader = FrameReader()
            resume = b'{"op":"call_service","service":"/rwt/player/resume","id":"go"}'
            cpu0, client0 = tree_cpu_s(process.pid), time.process_time()
            sock.sendall(client_frame(resume))
            got, wrong, first, last = 0, 0, 0.0, 0.0
            sock.settimeout(5.0)
            with contextlib.suppress(TimeoutError, ConnectionError):
                while got < count:
                    data = sock.recv(262144)
                    if not data:
                        break
                    for _, payload in reader.feed(data):
                        if not payload.startswith(b'{"op":"publish"'):
                            continue  # the resume's answer
                        if got == 0:
                            first = time.time()
                        wrong += payload != expected[got]
                        got += 1
                        last = time.time()
            cpu1 = tree_cpu_s(process.pid)
            client_s = time.process_time() - client0
    finally:
        _stop(process, signal.SIGTERM)
    if wrong:
        raise RuntimeError(f"rwt play: {wrong} messages differ from the bag's")
    return Measure(count, got, last - first, cpu1 - cpu0, client_s)


def play_rosbag(bag: Path, env: dict[str, str], count: int) -> Measure:
    """Real ``rosbag play --immediate`` to a rospy subscriber that checks every message."""
    options = ["--immediate", "--queue", str(count), "--wait-for-subscribers", "--quiet"]
    player = subprocess.Popen(
        ["rosbag", "play", *options, str(bag)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        subscriber = subprocess.run(
            [ROS_PYTHON, str(NODES), "sub-string", TOPIC, str(count), str(player.pid)],
            env=env,
            capture_output=True,
            timeout=_LIMIT_S,
            check=True,
        )
        result = json.loads(subscriber.stdout.splitlines()[-1])
    finally:
        _stop(player, signal.SIGINT)
    if result["wrong"]:
        raise RuntimeError(f"rosbag play: {result['wrong']} messages differ from the bag's")
    return Measure(count, result["got"], result["last"] - result["first"], result["cpu_s"])


# --- the run ------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """One row: what is measured and how each side runs one round of it."""

    key: str
    rwt: Callable[[], Measure]
    ros1: Callable[[], Measure]
    target: float


def _median(measures: list[Measure]) -> dict[str, float]:
    def med(values: list[float]) -> float:
        return statistics.median(values)

    return {
        "rate": med([m.rate for m in measures]),
        "sent": med([m.sent for m in measures]),
        "in_bag": med([m.in_bag for m in measures]),
        "drops_max": max(m.drops for m in measures),
        "cpu_pct": med([100 * m.cpu_s / m.window_s if m.window_s else 0.0 for m in measures]),
        "cpu_us_per_msg": med([1e6 * m.cpu_s / m.in_bag if m.in_bag else 0.0 for m in measures]),
    }


def run(runs: int, smoke: bool, log: Callable[[str], None] = print) -> dict[str, object]:
    """Every case, ``runs`` interleaved rounds each; medians and each round's figures.

    Raises:
        RuntimeError: a process did not start, or a message arrived wrong.
    """
    string_s, image_s, play_count = (0.3, 0.0, 300) if smoke else (3.0, 5.0, PLAY_COUNT)
    tmp = Path(tempfile.mkdtemp(prefix="rwt-b22-"))
    rows: list[dict[str, object]] = []
    try:
        with roscore(tmp) as env:
            bag = tmp / "play.bag"
            write_play_bag(bag, play_count)
            cases = [
                Case(
                    "record String 100 B, as fast as the publisher goes",
                    lambda: record_rwt(tmp, "string", string_s),
                    lambda: record_rosbag(tmp, env, "string", string_s),
                    1.0,
                ),
                Case(
                    f"play {play_count:,} String 100 B at full speed",
                    lambda: play_rwt(bag, play_count),
                    lambda: play_rosbag(bag, env, play_count),
                    0.5,
                ),
            ]
            if not smoke:  # the smoke test stays under 15 s
                image = Case(
                    "record Image 640x480 rgb8 at 30 Hz",
                    lambda: record_rwt(tmp, "image", image_s),
                    lambda: record_rosbag(tmp, env, "image", image_s),
                    1.0,
                )
                cases.insert(1, image)
            for case in cases:
                log(case.key)
                sides: dict[str, list[Measure]] = {"rwt": [], "ros1": []}
                for r in range(runs):
                    order = ("rwt", "ros1") if r % 2 == 0 else ("ros1", "rwt")
                    for side in order:
                        measure = case.rwt() if side == "rwt" else case.ros1()
                        sides[side].append(measure)
                        log(
                            f"  {side} round {r + 1}: {measure.rate:,.0f} msg/s,"
                            f" {measure.in_bag}/{measure.sent}, CPU {measure.cpu_s:.2f} s"
                        )
                        for leftover in tmp.glob("*.bag*"):
                            if leftover != bag:
                                leftover.unlink()
                rows.append(
                    {
                        "measure": case.key,
                        "target": case.target,
                        "rwt": _median(sides["rwt"]),
                        "ros1": _median(sides["ros1"]),
                        "rounds": {k: [vars(m) for m in v] for k, v in sides.items()},
                    }
                )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"runs": runs, "rows": rows}


def verdict(row: dict[str, object]) -> tuple[float, bool]:
    """The ratio rwt / rosbag of a row and whether its target is met.

    The ratio is judged as shown, to two decimals: a paced stream recorded whole
    on both sides is 1.00x even when one recorder took its last frame a few ms later.
    A record row also needs every published message in rwt's bag, in every round.
    """
    rwt, ros1 = row["rwt"], row["ros1"]
    ratio = rwt["rate"] / ros1["rate"] if ros1["rate"] else float("inf")  # type: ignore[index]
    met = round(ratio, 2) >= row["target"]  # type: ignore[operator]
    if str(row["measure"]).startswith("record"):
        met = met and rwt["drops_max"] == 0  # type: ignore[index]
    return ratio, met


def table(result: dict[str, object]) -> str:
    """The medians as a Markdown table, with the verdict of each target."""
    lines = [
        "| measure | rwt msg/s | rosbag msg/s | ratio | rwt: in bag / sent (drops, worst round)"
        " | rosbag: in bag / sent (drops, worst round) | CPU % of a core, rwt; rosbag"
        " | CPU us/msg, rwt; rosbag | target |",
        "|---|---:|---:|---:|---|---|---|---|---|",
    ]
    for row in result["rows"]:  # type: ignore[attr-defined]
        rwt, ros1 = row["rwt"], row["ros1"]
        ratio, met = verdict(row)
        playing = row["measure"].startswith("play")
        cpu_pct = "-" if playing else f"{rwt['cpu_pct']:.0f}; {ros1['cpu_pct']:.0f}"
        goal = f">= {row['target']}x" + ("" if playing else ", no drops")
        lines.append(
            f"| {row['measure']} | {rwt['rate']:,.0f} | {ros1['rate']:,.0f} | {ratio:.2f}x"
            f" | {rwt['in_bag']:,.0f} / {rwt['sent']:,.0f} ({rwt['drops_max']:,})"
            f" | {ros1['in_bag']:,.0f} / {ros1['sent']:,.0f} ({ros1['drops_max']:,})"
            f" | {cpu_pct} | {rwt['cpu_us_per_msg']:,.0f}; {ros1['cpu_us_per_msg']:,.0f}"
            f" | {goal}: {'met' if met else 'not met'} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run, print the table, save ``results/ros1_bag.json`` (not with --smoke)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks rosbag", description=__doc__)
    parser.add_argument("--runs", type=int, default=3, help="interleaved rounds per case")
    parser.add_argument("--smoke", action="store_true", help="one tiny round (tests)")
    args = parser.parse_args(argv)
    reason = missing()
    if reason:
        print(f"benchmarks rosbag: skipped: {reason}", file=sys.stderr)
        return 0

    def log(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    result = run(1 if args.smoke else args.runs, args.smoke, log)
    print(table(result))
    if not args.smoke:
        RESULTS.write_text(json.dumps(result, indent=2) + "\n", "utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
