"""``python -m benchmarks foxglove [--quick]``: rwt's Foxglove server beside the Foxglove SDK's.

Two robot processes run side by side for the whole run, each a Python program
with its server in process: one embeds rwt (``rwt.Graph`` publishers served by
``rwt.RosbridgeServer``, which answers ``foxglove.sdk.v1`` on its WebSocket
port), the other the Foxglove SDK from PyPI (``foxglove.start_server`` and
``Channel.log``, its Rust server). Both send the same bytes: CDR of
``std_msgs/msg/String`` and ``sensor_msgs/msg/Image`` with a ROS 2 schema. Both
robots pack the CDR themselves (a template and a counter: one copy per
message): the SDK's calls ``Channel.log`` with ``log_time`` set to the wall
clock, in a plain loop (its server runs on threads of its own); rwt's publishes
the bytes (``LocalPublisher.publish(bytes)``, docs/embedding.md) and yields to
its event loop (``asyncio.sleep(0)``), where its server runs, after each
message (``--rwt-yield-every N``: after every N), or after every ``BATCH`` in
the ``batch`` scenarios.
``--with-dicts`` adds a third robot, rwt's publishing dicts (the graph
validates and serializes them). ``--uvloop`` runs rwt's robots on uvloop
(``rwt serve --uvloop``, the ``uvloop`` extra), where a turn of the event loop
costs about half of asyncio's.

The readers are one separate process per scenario (``python -m
benchmarks.foxglove reader``): bare sockets in a ``selectors`` loop that cut
frames by hand, skip payloads past the 13 bytes of the message data header, and
count message data per subscription (their CPU is reported: they must not be
the bottleneck). Scenarios, each in interleaved rounds (rwt, SDK, SDK, rwt...)
and reported as medians:

- ``burst1``, ``burst10``: 20,000 x 100 B as fast as the robot sends, to 1 and
  10 readers: delivered %, delivered msg/s (all readers, from the first send to
  the last delivery), server CPU us per delivered message, and the robot's own
  rate of publish (``log``) calls, from its first to its last.
- ``batch1``, ``batch10``: the same, rwt's robot yielding every ``BATCH`` messages.
- ``large``: 2,000 x 100 kB to one reader: MB/s and loss.
- ``image1``, ``image5``: a 2 MB ``sensor_msgs/Image`` at 30 Hz to 1 and 5
  readers: p50 and p99 latency, from the log time in the message data header to
  the frame's last byte at the reader (one machine, one wall clock).
- ``alone``: 5,000 x 10 kB to one reader, the reference for ``stalled``.
- ``stalled``: 5,000 x 10 kB beside a reader that subscribed and never reads
  (a 16 kB receive buffer): the fast reader's delivered %, and the server
  process's resident memory growth (its peak, ``VmHWM``, over the start).

CPU is each robot process's own (``/proc/<pid>/task/*/schedstat``), robot code
included in both. The table goes to stdout and ``results/foxglove.json``;
README.md holds a run's table by hand.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import json
import os
import selectors
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .proctree import tree_cpu_ns

if TYPE_CHECKING:
    from collections.abc import Callable

RESULTS = Path(__file__).resolve().parent / "results"
BURST = "/burst"
IMAGE = "/image"
STRING_SCHEMA = b"string data\n"
SERVERS = ("rwt", "sdk")
IMAGE_W, IMAGE_H = 1000, 666  # rgb8: 1,998,000 bytes of pixels
BATCH = 100
"""Messages rwt's robot publishes between yields in ``batch1``/``batch10`` (docs/embedding.md)."""


@dataclass(frozen=True)
class Scenario:
    """One measurement: ``count`` messages of ``size`` bytes on ``topic`` to ``readers``."""

    name: str
    topic: str
    count: int
    size: int
    readers: int
    hz: float = 0.0  # 0: as fast as the robot sends
    stalled: bool = False
    batch: int = 0  # rwt's robot yields after this many messages (0: its --rwt-yield-every)


def scenarios(quick: bool) -> list[Scenario]:
    """The scenarios in run order (``quick``: tiny counts, for the smoke test)."""
    q = quick
    return [
        Scenario("burst1", BURST, 300 if q else 20_000, 100, 1),
        Scenario("burst10", BURST, 300 if q else 20_000, 100, 10),
        Scenario("batch1", BURST, 300 if q else 20_000, 100, 1, batch=BATCH),
        Scenario("batch10", BURST, 300 if q else 20_000, 100, 10, batch=BATCH),
        Scenario("large", BURST, 20 if q else 2_000, 100_000, 1),
        Scenario("image1", IMAGE, 5 if q else 150, IMAGE_W * IMAGE_H * 3, 1, hz=30.0),
        Scenario("image5", IMAGE, 5 if q else 150, IMAGE_W * IMAGE_H * 3, 5, hz=30.0),
        Scenario("alone", BURST, 200 if q else 5_000, 10_000, 1),  # ``stalled`` without it
        Scenario("stalled", BURST, 200 if q else 5_000, 10_000, 1, stalled=True),
    ]


# ---- the robots ----------------------------------------------------------------------


def _text(index: int, size: int) -> bytes:
    return f"{index:08d}".encode().ljust(size, b"x")


def _cdr_string(text: bytes) -> bytes:
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(text) + 1) + text + b"\x00"


def _image_msg(stamp_ns: int, pixels: bytes) -> dict[str, Any]:
    return {
        "header": {
            "stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9},
            "frame_id": "cam",
        },
        "height": IMAGE_H,
        "width": IMAGE_W,
        "encoding": "rgb8",
        "step": IMAGE_W * 3,
        "data": pixels,
    }


def _reply(value: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(value) + "\n")
    sys.stdout.flush()


def _rwt_robot() -> None:
    import asyncio  # noqa: PLC0415
    import logging  # noqa: PLC0415

    import anyio  # noqa: PLC0415

    import rwt  # noqa: PLC0415

    # the stalled reader's queue figures come from ``event=foxglove_closed`` (stderr)
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    logging.getLogger("rwt.foxglove").setLevel(logging.INFO)

    graph = rwt.Graph()
    burst = graph.create_publisher(BURST, "std_msgs/msg/String")
    image = graph.create_publisher(IMAGE, "sensor_msgs/msg/Image")
    pixels = bytes(IMAGE_W * IMAGE_H * 3)
    template = _image_template()
    server = rwt.RosbridgeServer(graph, rwt.ServerConfig(port=0))

    def subscribers(topic: str) -> int:
        entry = graph.port.topics.get(topic)
        return 0 if entry is None else len(entry.subscribers)

    async def send(cmd: dict[str, Any]) -> None:
        deadline = time.monotonic() + 60
        # the graph announces no subscription: it is looked at
        while subscribers(cmd["topic"]) < cmd["subs"] and time.monotonic() < deadline:  # noqa: ASYNC110
            await anyio.sleep(0.01)
        period = 1 / cmd["hz"] if cmd["hz"] else 0.0
        every = cmd.get("yield_every", 1)
        make_image, make_text = _rwt_messages(cmd.get("dicts", False), pixels, template)
        started = time.monotonic_ns()
        for index in range(cmd["count"]):
            if period:
                await anyio.sleep(max(0.0, started / 1e9 + index * period - time.monotonic()))
            if cmd["topic"] == IMAGE:
                image.publish(make_image(time.time_ns()))
            else:
                burst.publish(make_text(_text(index, cmd["size"])))
            if (index + 1) % every == 0:
                # asyncio's own yield: anyio's checkpoint asks sniffio for the
                # backend first, 1-2 us more a turn (docs/embedding.md)
                await asyncio.sleep(0)
        _reply({"started": started, "ended": time.monotonic_ns()})

    async def main() -> None:
        async with anyio.create_task_group() as tg:
            await tg.start(server.serve)
            _reply({"port": int(server.urls["websocket"].rsplit(":", 1)[1])})
            while line := await anyio.to_thread.run_sync(sys.stdin.readline):
                cmd = json.loads(line)
                if cmd["cmd"] == "quit":
                    break
                await send(cmd)
            server.stop()

    anyio.run(main, backend_options={"use_uvloop": "uvloop" in sys.argv[3:]})


def _rwt_messages(
    dicts: bool, pixels: bytes, template: bytes
) -> tuple[Callable[[int], object], Callable[[bytes], object]]:
    """What rwt's robot publishes: an image from its stamp, a String from its text.

    CDR, as the SDK's robot logs it, or (``dicts``) dicts the graph validates and serializes.
    """
    if dicts:
        return (lambda stamp: _image_msg(stamp, pixels)), (lambda text: {"data": text.decode()})
    return (lambda stamp: _stamped(template, stamp)), _cdr_string


def _stamped(template: bytes, stamp_ns: int) -> bytes:
    """The Image CDR ``template`` with its header stamp set to ``stamp_ns``."""
    stamp = struct.pack("<iI", stamp_ns // 10**9, stamp_ns % 10**9)
    return template[:4] + stamp + template[12:]


def _image_template() -> bytes:
    """The CDR of an Image with a zero stamp (rwt's serializer, once)."""
    import rwt  # noqa: PLC0415

    registry = rwt.Graph().registry
    mtype = registry.message("sensor_msgs/msg/Image")
    return bytes(
        registry.serialize(mtype, mtype.from_python(_image_msg(0, bytes(IMAGE_W * IMAGE_H * 3))))
    )


def _sdk_robot() -> None:
    from foxglove.websocket import ServerListener  # noqa: PLC0415

    import foxglove  # noqa: PLC0415
    import rwt  # noqa: PLC0415

    counts: dict[str, int] = {}

    class Listener(ServerListener):
        def on_subscribe(self, client: Any, channel: Any) -> None:
            counts[channel.topic] = counts.get(channel.topic, 0) + 1

        def on_unsubscribe(self, client: Any, channel: Any) -> None:
            counts[channel.topic] = counts.get(channel.topic, 0) - 1

    registry = rwt.Graph().registry
    image_schema = _ros2msg_schema(registry, "sensor_msgs/msg/Image")
    template = _image_template()
    server = foxglove.start_server(port=0, server_listener=Listener())
    burst = foxglove.Channel(
        BURST,
        message_encoding="cdr",
        schema=foxglove.Schema(name="std_msgs/msg/String", encoding="ros2msg", data=STRING_SCHEMA),
    )
    image = foxglove.Channel(
        IMAGE,
        message_encoding="cdr",
        schema=foxglove.Schema(name="sensor_msgs/msg/Image", encoding="ros2msg", data=image_schema),
    )
    _reply({"port": server.port})
    for line in sys.stdin:
        cmd = json.loads(line)
        if cmd["cmd"] == "quit":
            break
        deadline = time.monotonic() + 60
        while counts.get(cmd["topic"], 0) < cmd["subs"] and time.monotonic() < deadline:
            time.sleep(0.01)
        period = 1 / cmd["hz"] if cmd["hz"] else 0.0
        started = time.monotonic_ns()
        for index in range(cmd["count"]):
            if period:
                time.sleep(max(0.0, started / 1e9 + index * period - time.monotonic()))
            now = time.time_ns()
            if cmd["topic"] == IMAGE:
                image.log(_stamped(template, now), log_time=now)
            else:
                burst.log(_cdr_string(_text(index, cmd["size"])), log_time=now)
        _reply({"started": started, "ended": time.monotonic_ns()})
    server.stop()


def _ros2msg_schema(registry: Any, name: str) -> bytes:
    from rwt_foxglove.schemas import schema_of  # noqa: PLC0415

    return schema_of(registry.message(name)).schema.encode()


# ---- the readers ---------------------------------------------------------------------


@dataclass
class Reader:
    """One Foxglove connection on a bare socket; counts message data of one subscription."""

    sock: socket.socket
    topic: str
    latency: bool = False
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0
    latencies_ns: list[int] = field(default_factory=list)
    channel: int | None = None
    statuses: list[str] = field(default_factory=list)
    closed: bool = False
    head: int = 13
    """Bytes kept of each binary frame (a message data header is 13)."""
    _pending: bytes = b""
    _left: int = 0
    _opcode: int = 0
    _want: int = 0
    _collect: bytearray = field(default_factory=bytearray)

    @classmethod
    def open(
        cls, port: int, topic: str, *, latency: bool = False, rcvbuf: int | None = None
    ) -> Reader:
        """Connect, offer ``foxglove.sdk.v1``, wait for ``topic``'s channel and subscribe to it."""
        sock, rest = connect(port, rcvbuf=rcvbuf, protocol="foxglove.sdk.v1")
        reader = cls(sock, topic, latency)
        reader.feed(rest, 0)
        while reader.channel is None:
            chunk = sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed before the channel was advertised")
            reader.feed(chunk, 0)
        subscribe = {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": reader.channel}]}
        sock.sendall(_client_text(json.dumps(subscribe).encode()))
        sock.setblocking(False)
        return reader

    def feed(self, data: bytes, now_ns: int) -> None:
        """Cut ``data`` into frames: text ops whole, the first ``head`` bytes of binary ones."""
        if self._pending:
            data = self._pending + data
            self._pending = b""
        pos, end = 0, len(data)
        while pos < end:
            if self._left:
                take = min(self._left, end - pos)
                short = self._want - len(self._collect)
                if short > 0:
                    self._collect += data[pos : pos + min(take, short)]
                pos += take
                self._left -= take
                if not self._left:
                    self._done(now_ns)
                continue
            header = _frame_header(data, pos, end)
            if header is None:
                self._pending = data[pos:]
                return
            opcode, length, size = header
            pos += size
            self._opcode, self._left = opcode, length
            self._want = self.head if opcode == 2 else length
            self._collect = bytearray()
            if not length:
                self._done(now_ns)

    def _done(self, now_ns: int) -> None:
        body = self._collect
        if self._opcode == 2 and body[:1] == b"\x01":
            self.count += 1
            if not self.first_ns:
                self.first_ns = now_ns
            self.last_ns = now_ns
            if self.latency:
                log_time = int.from_bytes(body[5:13], "little")
                self.latencies_ns.append(time.time_ns() - log_time)
        elif self._opcode == 1:
            op = json.loads(body)
            if op.get("op") == "advertise":
                for channel in op["channels"]:
                    if channel["topic"] == self.topic:
                        self.channel = channel["id"]
            elif op.get("op") == "status":
                self.statuses.append(str(op.get("message")))
        elif self._opcode == 8:
            self.closed = True

    def close(self) -> None:
        """Send a close frame (masked, no code) and close the socket."""
        try:
            self.sock.setblocking(True)
            self.sock.settimeout(1)
            self.sock.sendall(b"\x88\x80\0\0\0\0")
        except OSError:
            pass  # the peer is gone already
        self.sock.close()


def connect(
    port: int, *, rcvbuf: int | None = None, protocol: str | None = None
) -> tuple[socket.socket, bytes]:
    """A WebSocket client connection to 127.0.0.1:``port`` (offering ``protocol`` if
    given) on a blocking socket; the bytes that came after the handshake's response.

    Raises:
        ConnectionError: the server closed the connection or refused the handshake.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    if rcvbuf is not None:  # before connect: the window stays small
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    sock.settimeout(30)
    sock.connect(("127.0.0.1", port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    key = base64.b64encode(os.urandom(16)).decode()
    offer = f"Sec-WebSocket-Protocol: {protocol}\r\n" if protocol else ""
    sock.sendall(
        (
            f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
            f"{offer}\r\n"
        ).encode()
    )
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError("closed during the handshake")
        data += chunk
    head, _, rest = data.partition(b"\r\n\r\n")
    if not head.startswith(b"HTTP/1.1 101"):
        raise ConnectionError(f"handshake refused: {head[:80]!r}")
    return sock, rest


def _frame_header(data: bytes, pos: int, end: int) -> tuple[int, int, int] | None:
    """(opcode, payload length, header size) of the server frame at ``pos``; None: incomplete."""
    if end - pos < 2:
        return None
    opcode, length = data[pos] & 0x0F, data[pos + 1] & 0x7F
    if length < 126:
        return opcode, length, 2
    size = 4 if length == 126 else 10
    if end - pos < size:
        return None
    return opcode, int.from_bytes(data[pos + 2 : pos + size], "big"), size


def _client_text(payload: bytes) -> bytes:
    """A masked (zero key) client text frame."""
    if len(payload) < 126:
        head = bytes((0x81, 0x80 | len(payload)))
    else:
        head = struct.pack("!BBH", 0x81, 0x80 | 126, len(payload))
    return head + b"\0\0\0\0" + payload


def read_all(readers: list[Reader], expect: int, idle_s: float, first_wait_s: float) -> None:
    """Read every connection until each counted ``expect`` or nothing came for ``idle_s``."""
    sel = selectors.DefaultSelector()
    for reader in readers:
        sel.register(reader.sock, selectors.EVENT_READ, reader)
    last_data = time.monotonic() + first_wait_s - idle_s
    done = sum(r.count >= expect for r in readers)
    while done < len(readers) and time.monotonic() - last_data < idle_s:
        for key, _ in sel.select(0.2):
            reader = key.data
            try:
                chunk = reader.sock.recv(1 << 20)
            except BlockingIOError:
                continue
            if not chunk:
                sel.unregister(reader.sock)
                reader.closed = True
                continue
            last_data = time.monotonic()
            before = reader.count >= expect
            reader.feed(chunk, time.monotonic_ns())
            done += (reader.count >= expect) and not before
    sel.close()


def reader_main(argv: list[str]) -> int:
    """The reader process: ``--port --topic --readers --expect [--latency]``; JSON on stdout."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.foxglove reader")
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--topic", required=True)
    parser.add_argument("--readers", type=int, default=1)
    parser.add_argument("--expect", type=int, required=True)
    parser.add_argument("--latency", action="store_true")
    parser.add_argument("--idle", type=float, default=3.0)
    args = parser.parse_args(argv)
    readers = [
        Reader.open(args.port, args.topic, latency=args.latency) for _ in range(args.readers)
    ]
    cpu0, wall0 = time.process_time_ns(), time.monotonic_ns()
    _reply({"ready": True})
    read_all(readers, args.expect, args.idle, first_wait_s=60.0)
    cpu, wall = time.process_time_ns() - cpu0, time.monotonic_ns() - wall0
    _reply(
        {
            "counts": [r.count for r in readers],
            "first_ns": min((r.first_ns for r in readers if r.first_ns), default=0),
            "last_ns": max(r.last_ns for r in readers),
            "latencies_ns": [x for r in readers for x in r.latencies_ns],
            "statuses": sorted({s for r in readers for s in r.statuses}),
            "closed": sum(r.closed for r in readers),
            "cpu_ns": cpu,
            "wall_ns": wall,
        }
    )
    for reader in readers:
        reader.close()
    return 0


# ---- the harness ---------------------------------------------------------------------


class Robot:
    """A robot process (``rwt`` or ``sdk``) and its server's port."""

    def __init__(
        self,
        kind: str,
        yield_every: int = 1,
        src: str | None = None,
        *,
        dicts: bool = False,
        uvloop: bool = False,
    ) -> None:
        self.kind = kind  # ``base``: rwt's robot on the rwt source at ``src``
        self.yield_every = yield_every  # rwt's robot: messages between yields to its loop
        self.dicts = dicts  # rwt's robot: publishes dicts, not CDR
        env = None
        if src is not None:
            env = dict(os.environ, PYTHONPATH=os.pathsep.join((src, str(Path.cwd()))))
        # its log (the SDK's line per failed send to the stalled reader, rwt's
        # slow_consumer) is shown only if it fails
        self.log = tempfile.TemporaryFile("w+")  # noqa: SIM115 (kept while the robot runs)
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "benchmarks.foxglove",
                "robot",
                "sdk" if kind == "sdk" else "rwt",
                *(["uvloop"] if uvloop and kind != "sdk" else []),
            ],
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.log,
            text=True,
        )
        self.port = int(self._line()["port"])

    def _line(self) -> dict[str, Any]:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            code = self.proc.wait()
            self.log.seek(0)
            tail = self.log.read()[-3000:]
            raise RuntimeError(f"the {self.kind} robot ended (exit {code}):\n{tail}")
        return json.loads(line)  # type: ignore[no-any-return]

    def send(self, scenario: Scenario, subs: int) -> dict[str, Any]:
        """Have the robot send ``scenario``'s messages once ``subs`` subscriptions exist."""
        assert self.proc.stdin is not None
        cmd = {
            "cmd": "send",
            "topic": scenario.topic,
            "count": scenario.count,
            "size": scenario.size,
            "hz": scenario.hz,
            "subs": subs,
            "yield_every": scenario.batch or self.yield_every,
            "dicts": self.dicts,
        }
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()
        return self._line()

    def memory_kb(self) -> tuple[int, int]:
        """(VmRSS, VmHWM) of the robot process in kB."""
        fields = dict(
            line.split(":", 1)
            for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines()
        )
        return int(fields["VmRSS"].split()[0]), int(fields["VmHWM"].split()[0])

    def stalled_queue(self, local_port: int, wait_s: float = 10.0) -> tuple[int, int]:
        """(dropped, queue peak bytes) of the rwt client from ``local_port``, from its log.

        rwt logs ``event=foxglove_closed client=ws:127.0.0.1:<port>#<n> dropped=N
        queue_peak_bytes=B`` when a Foxglove connection ends; (-1, -1) if no such
        line came in ``wait_s``.
        """
        client = f"client=ws:127.0.0.1:{local_port}#"
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            self.log.seek(0)
            lines = [
                line for line in self.log if "event=foxglove_closed" in line and client in line
            ]
            self.log.seek(0, 2)
            if lines:
                fields = dict(part.split("=", 1) for part in lines[-1].split() if "=" in part)
                return int(fields["dropped"]), int(fields["queue_peak_bytes"])
            time.sleep(0.05)
        return -1, -1

    def reset_peak(self) -> None:
        """Start ``VmHWM`` again from the current RSS (``clear_refs`` 5; Linux 4.0)."""
        # not allowed: the peak is the process's lifetime peak
        with contextlib.suppress(OSError):
            Path(f"/proc/{self.proc.pid}/clear_refs").write_text("5")

    def close(self) -> None:
        if self.proc.poll() is None:
            assert self.proc.stdin is not None
            try:
                self.proc.stdin.write(json.dumps({"cmd": "quit"}) + "\n")
                self.proc.stdin.flush()
                self.proc.wait(10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()
        self.log.close()


def run_once(robot: Robot, scenario: Scenario, idle_s: float) -> dict[str, Any]:
    """One round of ``scenario`` on ``robot``: its figures."""
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.foxglove",
        "reader",
        f"--port={robot.port}",
        f"--topic={scenario.topic}",
        f"--readers={scenario.readers}",
        f"--expect={scenario.count}",
        f"--idle={idle_s}",
    ]
    if scenario.hz:
        cmd.append("--latency")
    reader = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    stalled: Reader | None = None
    stalled_port = 0
    try:
        assert reader.stdout is not None
        if not json.loads(reader.stdout.readline() or "{}").get("ready"):
            raise RuntimeError("the reader did not start")
        if scenario.stalled:  # subscribes, then never reads
            stalled = Reader.open(robot.port, scenario.topic, rcvbuf=16384)
            stalled_port = stalled.sock.getsockname()[1]
        robot.reset_peak()
        memory0 = robot.memory_kb()
        cpu0 = tree_cpu_ns(robot.proc.pid)
        sent = robot.send(scenario, scenario.readers + (1 if stalled else 0))
        result = json.loads(reader.stdout.readline())
        cpu = tree_cpu_ns(robot.proc.pid) - cpu0
        memory1 = robot.memory_kb()
        reader.wait(30)
    finally:
        if reader.poll() is None:
            reader.kill()
            reader.wait()
        if stalled is not None:
            stalled.sock.close()  # unread data: the server sees a reset
    if stalled is not None and robot.kind != "sdk":
        dropped, peak = robot.stalled_queue(stalled_port)
        result["stalled_dropped"], result["queue_peak_mb"] = dropped, peak / 1e6
    delivered = sum(result["counts"])
    expected = scenario.count * scenario.readers
    span_s = max(result["last_ns"] - sent["started"], 1) / 1e9
    out: dict[str, Any] = {
        "delivered": delivered,
        "expected": expected,
        "delivered_pct": 100.0 * delivered / expected,
        "msg_per_s": delivered / span_s,
        "sent_per_s": scenario.count / (max(sent["ended"] - sent["started"], 1) / 1e9),
        "mb_per_s": delivered * scenario.size / span_s / 1e6,
        "cpu_us_per_msg": cpu / 1e3 / max(delivered, 1),
        "reader_cpu_pct": 100.0 * result["cpu_ns"] / max(result["last_ns"] - sent["started"], 1),
        "statuses": result["statuses"],
        "closed": result["closed"],
    }
    if result["latencies_ns"]:
        lat = sorted(result["latencies_ns"])
        out["p50_ms"] = lat[len(lat) // 2] / 1e6
        out["p99_ms"] = lat[min(len(lat) - 1, int(len(lat) * 0.99))] / 1e6
    if scenario.stalled:
        for key in ("stalled_dropped", "queue_peak_mb"):
            if key in result:
                out[key] = result[key]
        out["rss_growth_mb"] = (memory1[0] - memory0[0]) / 1024
        out["peak_growth_mb"] = (memory1[1] - memory0[0]) / 1024
    return out


def _median(runs: list[dict[str, Any]], key: str) -> float | None:
    values = [r[key] for r in runs if key in r]
    return statistics.median(values) if values else None


ROWS: list[tuple[str, str, str]] = [
    # scenario, figure, what it is
    ("burst1", "delivered_pct", "delivered %"),
    ("burst1", "msg_per_s", "delivered msg/s"),
    ("burst1", "cpu_us_per_msg", "server CPU us/delivered msg"),
    ("burst1", "sent_per_s", "the robot's publish calls/s"),
    ("burst10", "delivered_pct", "delivered %"),
    ("burst10", "msg_per_s", "delivered msg/s"),
    ("burst10", "cpu_us_per_msg", "server CPU us/delivered msg"),
    ("burst10", "sent_per_s", "the robot's publish calls/s"),
    ("batch1", "delivered_pct", "delivered %"),
    ("batch1", "msg_per_s", "delivered msg/s"),
    ("batch1", "cpu_us_per_msg", "server CPU us/delivered msg"),
    ("batch10", "delivered_pct", "delivered %"),
    ("batch10", "msg_per_s", "delivered msg/s"),
    ("batch10", "cpu_us_per_msg", "server CPU us/delivered msg"),
    ("large", "mb_per_s", "MB/s"),
    ("large", "delivered_pct", "delivered %"),
    ("large", "cpu_us_per_msg", "server CPU us/delivered msg"),
    ("large", "sent_per_s", "the robot's publish calls/s"),
    ("image1", "p50_ms", "p50 latency ms"),
    ("image1", "p99_ms", "p99 latency ms"),
    ("image1", "delivered_pct", "delivered %"),
    ("image5", "p50_ms", "p50 latency ms"),
    ("image5", "p99_ms", "p99 latency ms"),
    ("image5", "delivered_pct", "delivered %"),
    ("image5", "cpu_us_per_msg", "server CPU us/delivered msg"),
    ("alone", "delivered_pct", "delivered %"),
    ("stalled", "delivered_pct", "the fast reader's delivered %"),
    ("stalled", "stalled_dropped", "messages dropped for the stalled reader (rwt's log)"),
    ("stalled", "queue_peak_mb", "the stalled reader's queue at its peak, MB (rwt's log)"),
    ("stalled", "rss_growth_mb", "server RSS growth MB"),
    ("stalled", "peak_growth_mb", "server peak RSS growth MB"),
]


def title(scenario: Scenario) -> str:
    """``20,000 x 100 B to 10 readers``, ``2 MB Image at 30 Hz to 5 readers``..."""
    size = scenario.size
    shown = (
        f"{size / 1e6:.0f} MB"
        if size >= 10**6
        else f"{size // 1000} kB"
        if size >= 1000
        else f"{size} B"
    )
    what = (
        f"{shown} Image at {scenario.hz:.0f} Hz" if scenario.hz else f"{scenario.count:,} x {shown}"
    )
    readers = f"to {scenario.readers} reader{'s' if scenario.readers > 1 else ''}"
    batch = f", rwt's robot yielding every {scenario.batch}" if scenario.batch else ""
    return f"{what} {readers}{batch}" + (" beside a stalled one" if scenario.stalled else "")


def table(results: dict[str, dict[str, list[dict[str, Any]]]], rounds: int, quick: bool) -> str:
    """The markdown table: medians of the rounds, rwt, SDK, rwt/SDK, and the readers' CPU.

    With a third robot (``base``: ``--base-src``; ``dicts``: ``--with-dicts``): its
    column and rwt over it too.
    """
    titles = {scenario.name: title(scenario) for scenario in scenarios(quick)}
    third = next((k for runs in results.values() for k in runs if k not in SERVERS), None)
    base = third is not None
    extra = (f" rwt {third} | rwt/{third} |", "---|---|") if base else ("", "")
    lines = [
        f"| measure (median of {rounds} rounds) | rwt | Foxglove SDK | rwt/SDK |{extra[0]}",
        f"|---|---|---|---|{extra[1]}",
    ]
    for name, key, label in ROWS:
        if name not in results:
            continue
        rwt = _median(results[name]["rwt"], key)
        sdk = _median(results[name]["sdk"], key)
        ratio = f"{rwt / sdk:.2f}" if rwt is not None and sdk else "-"
        line = f"| {titles[name]}: {label} | {_fmt(rwt)} | {_fmt(sdk)} | {ratio} |"
        if base:
            before = _median(results[name][str(third)], key)
            change = f"{rwt / before:.2f}" if rwt is not None and before else "-"
            line += f" {_fmt(before)} | {change} |"
        lines.append(line)
    for name, runs in results.items():
        cpu = [_median(runs[kind], "reader_cpu_pct") for kind in (*SERVERS, third) if kind in runs]
        shown = " | ".join(_fmt(value) for value in cpu[:2])
        more = f" {_fmt(cpu[2])} | - |" if base and len(cpu) > 2 else ""
        lines.append(
            f"| {titles[name]}: the reader process's CPU, % of one core | {shown} | - |{more}"
        )
    return "\n".join(lines)


def _fmt(value: float | None) -> str:
    if value is None:
        return "-"
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    return f"{value:.3g}" if abs(value) < 10 else f"{value:.1f}"


def run(
    quick: bool,
    rounds: int,
    only: list[str],
    yield_every: int = 1,
    base_src: str | None = None,
    *,
    dicts: bool = False,
    uvloop: bool = False,
) -> dict[str, Any]:
    """Start both robots, run every scenario in interleaved rounds; the results by scenario.

    ``yield_every``: messages rwt's robot publishes between two yields to its event loop.
    ``base_src``: a third robot, ``base``, runs rwt from this ``src`` directory (another
    commit's) in the same rounds: before and after a change in one run.
    ``dicts``: the third robot publishes dicts, not CDR: ``base`` (an rwt from before
    ``publish(bytes)``), or without ``base_src`` one of its own, ``dicts``, on this rwt.
    ``uvloop``: rwt's robots run on uvloop.
    """
    idle_s = 1.5 if quick else 3.0
    third = "base" if base_src is not None else "dicts" if dicts else None
    kinds = SERVERS if third is None else (*SERVERS, third)
    robots = {
        kind: Robot(
            kind,
            1 if kind == "sdk" else yield_every,
            base_src if kind == "base" else None,
            dicts=kind == "dicts" or (kind == "base" and dicts),
            uvloop=uvloop,
        )
        for kind in kinds
    }
    results: dict[str, dict[str, list[dict[str, Any]]]] = {}
    try:
        warmup = Scenario("warmup", BURST, 1000, 100, 1)
        for robot in robots.values():  # first connections, imports, caches: not measured
            run_once(robot, warmup, idle_s)
        for scenario in scenarios(quick):
            if only and scenario.name not in only:
                continue
            runs: dict[str, list[dict[str, Any]]] = {kind: [] for kind in kinds}
            for index in range(rounds):
                order = kinds if index % 2 == 0 else kinds[::-1]
                for kind in order:
                    figures = run_once(robots[kind], scenario, idle_s)
                    runs[kind].append(figures)
                    shown = {
                        k: round(v, 3) if isinstance(v, float) else v for k, v in figures.items()
                    }
                    print(
                        f"{scenario.name} {kind} round {index + 1}: {shown}",
                        file=sys.stderr,
                        flush=True,
                    )
            results[scenario.name] = runs
    finally:
        for robot in robots.values():
            robot.close()
    return results


def main(argv: list[str]) -> int:
    """``python -m benchmarks foxglove [--quick] [--rounds N] [--only NAME...]``."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks foxglove", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="tiny counts, one round (smoke)")
    parser.add_argument("--rounds", type=int, default=None, help="rounds per server (default 3)")
    parser.add_argument("--only", nargs="*", default=[], help="scenario names to run")
    parser.add_argument(
        "--rwt-yield-every",
        type=int,
        default=1,
        help="messages rwt's robot publishes between yields to its loop (default 1)",
    )
    parser.add_argument(
        "--base-src",
        default=None,
        help="also run rwt from this src directory (another commit's, e.g. a `git archive` of it)"
        " in the same rounds: column `rwt base`",
    )
    parser.add_argument(
        "--with-dicts",
        action="store_true",
        help="also run rwt's robot publishing dicts (the graph serializes them) in the same"
        " rounds: column `rwt dicts`; with --base-src, the base robot publishes dicts",
    )
    parser.add_argument(
        "--uvloop", action="store_true", help="rwt's robots run on uvloop (rwt serve --uvloop)"
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="the JSON results (default: results/foxglove.json)"
    )
    args = parser.parse_args(argv)
    rounds = args.rounds or (1 if args.quick else 3)
    started = time.perf_counter()
    results = run(
        args.quick,
        rounds,
        args.only,
        max(1, args.rwt_yield_every),
        args.base_src,
        dicts=args.with_dicts,
        uvloop=args.uvloop,
    )
    text = table(results, rounds, args.quick)
    print(text)
    out = args.out or (None if args.quick else RESULTS / "foxglove.json")
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        payload = {
            "rounds": rounds,
            "quick": args.quick,
            "uvloop": args.uvloop,
            "minutes": (time.perf_counter() - started) / 60,
        }
        out.write_text(json.dumps(payload | {"results": results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["robot"]:
        _rwt_robot() if sys.argv[2] == "rwt" else _sdk_robot()
        sys.exit(0)
    if sys.argv[1:2] == ["reader"]:
        sys.exit(reader_main(sys.argv[2:]))
    sys.exit(main(sys.argv[1:]))
