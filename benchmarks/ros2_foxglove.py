"""``python -m benchmarks ros2 --foxglove``: ROS 2 images to Foxglove readers via rwt.

One ``rwt serve --ros2 --no-tf`` (this checkout) runs for the whole run. Each
round, a real rclpy publisher (ros2_bridge.py's, its own process) sends a 1 MB
``sensor_msgs/msg/Image`` (``WIDTH`` x ``HEIGHT`` ``rgb8``, all zero bytes, the
publish time in its header stamp) on a fresh topic at 30 Hz or as fast as rclpy
goes, to ``READERS`` WebSocket readers of one kind (``KINDS``), all in this
process:

- ``foxglove``: ``foxglove.sdk.v1`` readers on bare sockets (foxglove.py's
  ``Reader``), which get the CDR as it came from DDS in message data frames and
  read the stamp from the CDR header;
- ``cbor-raw``: rosbridge subscribers asking for ``cbor-raw`` (the same CDR in a
  CBOR ``publish``), bare sockets too, stamp from the CDR header;
- ``json``: rosbridge JSON subscribers (ros2_client.py's ``LeanCounter``: the
  stamp from the JSON, each image's base64 checked in place).

The readers of the Foxglove and cbor-raw kinds run in one thread (a ``selectors``
loop); the JSON ones on this process's event loop. Kinds take turns in each round
(the order rotates) and the table gives medians over the rounds. Per round:
delivered % (deliveries / (sent x readers)), delivered msg/s (all readers, first
timed publish to last delivery), p50 and p99 latency (the reader's
``time.time()`` when a frame's last byte is read minus the header stamp: one
machine, one clock), the server's CPU per delivery in us (user + system of the
whole ``rwt serve`` process, every thread, from ``/proc/<pid>/stat``, from the
first timed publish to the last delivery) and this process's CPU share (the
readers'; 1.0 = one core).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import selectors
import statistics
import struct
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from .foxglove import Reader, _client_text, connect
from .ros2_bridge import (
    DISCOVERY_S,
    IDLE_S,
    PUB,
    _child,
    _cpu,
    _line,
    _percentile,
    _say,
    _settle,
    _start_rwt,
    ros_env,
)
from .ros2_client import TYPES, LeanCounter
from .servers import rwt_pythonpath

__all__ = ["KINDS", "Round", "cdr_stamp", "main", "run", "table"]

WIDTH, HEIGHT = 1000, 334
"""The image: 1000x334 ``rgb8``, 1,002,000 bytes of pixels."""
READERS = 5
RATES = (30, 0)
"""Image rates in Hz; 0: as fast as the rclpy publisher goes."""
KINDS = ("foxglove", "cbor-raw", "json")
LABELS = {
    "foxglove": "Foxglove (foxglove.sdk.v1, CDR)",
    "cbor-raw": "rosbridge cbor-raw (CDR)",
    "json": "rosbridge JSON",
}
CDR_HEAD = 64
"""Bytes of the CDR kept: encapsulation (4), stamp (8), frame_id's length (4) and text."""


def cdr_stamp(cdr: bytes | bytearray) -> float | None:
    """The header stamp (s) of an Image's CDR (its first bytes suffice); None for a probe
    (``frame_id`` ``probe``).

    Raises:
        ValueError: fewer than 16 bytes.
    """
    if len(cdr) < 16:
        raise ValueError(f"{len(cdr)} B is no Image header")
    order = "<" if cdr[1] & 1 else ">"  # the encapsulation's endianness (CDR_LE: 0x0001)
    sec, nanosec, length = struct.unpack_from(order + "iII", cdr, 4)
    if cdr[16 : 16 + length].rstrip(b"\0") == b"probe":
        return None
    return sec + nanosec / 1e9


@dataclass
class _Stamped(Reader):
    """A reader whose binary frames carry an Image's CDR; its timed deliveries' latencies (s)."""

    latencies: list[float] = field(default_factory=list)
    probes: int = 0
    last: float = 0.0

    def _cdr(self, body: bytearray) -> bytearray | None:
        """The CDR's first bytes in a binary frame's ``body``; None: not a message."""
        raise NotImplementedError

    def _done(self, now_ns: int) -> None:
        cdr = self._cdr(self._collect) if self._opcode == 2 else None
        if cdr is None:
            super()._done(now_ns)
            return
        now = time.time()
        sent = cdr_stamp(cdr)
        if sent is None:
            self.probes += 1
            return
        self.count += 1
        self.latencies.append(now - sent)
        self.last = now


@dataclass
class FoxgloveStamped(_Stamped):
    """A Foxglove reader: message data frames (opcode 1, 13 bytes of header, then CDR)."""

    head: int = 13 + CDR_HEAD

    def _cdr(self, body: bytearray) -> bytearray | None:
        return body[13:] if body[:1] == b"\x01" else None


@dataclass
class CborRawStamped(_Stamped):
    """A rosbridge subscriber asking for ``cbor-raw``: a CBOR ``publish`` whose ``msg.bytes``
    is the CDR."""

    head: int = 512

    @classmethod
    def subscribe(cls, port: int, topic: str) -> CborRawStamped:
        """Connect to the rosbridge protocol on ``port`` and subscribe to ``topic`` (an Image)."""
        sock, rest = connect(port)
        reader = cls(sock, topic)
        op = {"op": "subscribe", "topic": topic, "type": TYPES["image"], "compression": "cbor-raw"}
        sock.sendall(_client_text(json.dumps(op).encode()))
        reader.feed(rest, 0)
        sock.setblocking(False)
        return reader

    def _cdr(self, body: bytearray) -> bytearray | None:
        at = body.find(b"\x65bytes")  # the text key "bytes", then a byte string's head
        if at < 0 or at + 7 > len(body) or body[at + 6] >> 5 != 2:
            raise ConnectionError(f"no CDR in a cbor-raw frame: {bytes(body[:80])!r}")
        info = body[at + 6] & 31
        skip = {24: 1, 25: 2, 26: 4, 27: 8}.get(info, 0)
        return body[at + 7 + skip :]


class _Group:
    """``count`` readers of one kind on one topic."""

    def __init__(self, kind: str, count: int) -> None:
        self.kind = kind
        self.count = count
        self.readers: list[_Stamped] = []
        self.counters: list[LeanCounter] = []
        self.tasks: list[asyncio.Task[None]] = []
        self.stop = threading.Event()
        self.thread: threading.Thread | None = None
        self.error: BaseException | None = None

    async def open(self, port: int, topic: str) -> None:
        """Connect and subscribe every reader (a Foxglove one waits for the channel)."""
        if self.kind == "json":
            self.counters = [LeanCounter(WIDTH * HEIGHT * 3) for _ in range(self.count)]
            url = f"ws://127.0.0.1:{port}"
            self.tasks = [asyncio.create_task(c.run(url, topic, "image")) for c in self.counters]
            return
        for _ in range(self.count):
            if self.kind == "foxglove":
                reader: _Stamped = await asyncio.to_thread(FoxgloveStamped.open, port, topic)
            else:
                reader = await asyncio.to_thread(CborRawStamped.subscribe, port, topic)
            self.readers.append(reader)
        self.thread = threading.Thread(target=self._pump, daemon=True)
        self.thread.start()

    def _pump(self) -> None:
        sel = selectors.DefaultSelector()
        for reader in self.readers:
            sel.register(reader.sock, selectors.EVENT_READ, reader)
        try:
            while not self.stop.is_set():
                for key, _ in sel.select(0.1):
                    with contextlib.suppress(BlockingIOError):
                        chunk = key.data.sock.recv(1 << 20)
                        if not chunk:
                            raise ConnectionError("the server closed a reader")
                        key.data.feed(chunk, time.monotonic_ns())
        except Exception as error:  # reported by ``close``
            self.error = error
        finally:
            sel.close()

    def probed(self) -> bool:
        """Whether every reader got a probe."""
        if self.kind == "json":
            return all(c.probed.is_set() for c in self.counters)
        return all(r.probes for r in self.readers)

    def failed(self) -> BaseException | None:
        """A reader's failure so far, if any."""
        for task in self.tasks:
            if task.done() and not task.cancelled() and task.exception() is not None:
                return task.exception()
        return self.error

    def latencies(self) -> list[float]:
        """Every timed delivery's latency (s), all readers."""
        each = self.counters if self.kind == "json" else self.readers
        return [x for r in each for x in r.latencies]

    def delivered(self) -> int:
        """Timed deliveries so far, all readers."""
        each = self.counters if self.kind == "json" else self.readers
        return sum(len(r.latencies) for r in each)

    def last(self) -> float:
        """``time.time()`` of the last timed delivery."""
        each = self.counters if self.kind == "json" else self.readers
        return max((r.last for r in each), default=0.0)

    async def close(self) -> None:
        """Stop and close every reader.

        Raises:
            RuntimeError: a reader failed (a wrong delivery, a closed connection).
        """
        error = self.failed()
        for task in self.tasks:
            task.cancel()
        await asyncio.gather(*self.tasks, return_exceptions=True)
        self.stop.set()
        if self.thread is not None:
            await asyncio.to_thread(self.thread.join)
        for reader in self.readers:
            reader.close()
        if error is not None:
            raise RuntimeError(f"a {self.kind} reader failed: {error!r}") from error


@dataclass(slots=True)
class Round:
    """One kind's figures in one round (module docstring)."""

    kind: str
    hz: int
    readers: int
    sent: int
    delivered: int
    delivered_pct: float
    msg_per_s: float
    p50_ms: float
    p99_ms: float
    cpu_us_per_delivery: float
    readers_cpu: float


async def _wait(group: _Group, within: float) -> None:
    end = time.monotonic() + within
    while not group.probed():
        if (error := group.failed()) is not None:
            raise RuntimeError(f"a {group.kind} reader failed: {error!r}") from error
        if time.monotonic() > end:
            raise TimeoutError(f"the {group.kind} readers got no probe in {within} s")
        await asyncio.sleep(0.05)


async def measure(
    kind: str,
    hz: int,
    seconds: float,
    port: int,
    pid: int,
    env: dict[str, str],
    tag: str,
    readers: int = READERS,
) -> Round:
    """One round of ``readers`` readers of ``kind`` at ``hz`` (0: as fast as it goes) on
    the server ``port``/``pid``; ``tag`` makes the round's topic name unique.

    Raises:
        RuntimeError: a reader failed or a process ended early.
        TimeoutError: a reader got no probe within ``DISCOVERY_S``.
    """
    topic = f"/fox_{kind.replace('-', '_')}_{hz}_{tag}"
    group = _Group(kind, readers)
    size = (str(WIDTH), str(HEIGHT))
    async with _child(PUB, "image", str(hz), str(seconds), topic, *size, env=env) as pub:
        await _line(pub)  # ready
        try:
            await asyncio.wait_for(group.open(port, topic), DISCOVERY_S)
            await _wait(group, DISCOVERY_S)
            await _settle(pid)
            await _say(pub)
            start = float((await _line(pub)).split()[0])  # the publish start, then its probes
            cpu0, own0 = _cpu(pid), time.process_time()
            sent_task = asyncio.create_task(_line(pub, seconds + DISCOVERY_S))
            cpu1, total, idle_since = cpu0, -1, time.monotonic()
            while not (sent_task.done() and time.monotonic() - idle_since > IDLE_S):
                await asyncio.sleep(0.1)
                if group.failed() is not None:
                    break
                if (now_total := group.delivered()) != total:
                    total, idle_since, cpu1 = now_total, time.monotonic(), _cpu(pid)
            own = time.process_time() - own0
            sent = int(await sent_task)
        finally:
            await group.close()
    latencies = group.latencies()
    delivered = len(latencies)
    span = max(group.last() - start, 1e-9)
    return Round(
        kind=kind,
        hz=hz,
        readers=readers,
        sent=sent,
        delivered=delivered,
        delivered_pct=100.0 * delivered / max(sent * readers, 1),
        msg_per_s=delivered / span if delivered else 0.0,
        p50_ms=_percentile(latencies, 0.5) * 1e3,
        p99_ms=_percentile(latencies, 0.99) * 1e3,
        cpu_us_per_delivery=(cpu1 - cpu0) / max(delivered, 1) * 1e6,
        readers_cpu=own / span,
    )


async def run(
    rounds: int,
    seconds: float,
    rates: list[int],
    kinds: list[str],
    domain: int,
    fastdds: str = "large-shm",
    readers: int = READERS,
) -> list[Round]:
    """Every rate, ``rounds`` rounds of every kind (the order rotating) with ``readers``
    readers each, on one rwt server (ROS 2 ``domain``, Fast DDS setup ``fastdds``).

    Raises:
        RuntimeError: a reader failed or a process ended early.
        TimeoutError: a reader got no probe within ``DISCOVERY_S``.
    """
    env = {**os.environ, **ros_env(domain, fastdds)}
    env["PYTHONPATH"] = rwt_pythonpath()
    results = []
    # the server logs at INFO (its per-stage counts); kept aside, not read here
    with (
        tempfile.TemporaryFile() as log,
        await asyncio.to_thread(_start_rwt, domain, env, log) as server,
    ):
        for hz in rates:
            for index in range(rounds):
                shift = index % len(kinds)
                for kind in kinds[shift:] + kinds[:shift]:
                    tag = f"{index}_{os.getpid()}"
                    pid = server.process.pid
                    figures = await measure(kind, hz, seconds, server.port, pid, env, tag, readers)
                    print(f"{kind} {hz or 'max'} Hz round {index + 1}: {figures}", file=sys.stderr)
                    results.append(figures)
    return results


def _median(rounds: list[Round], key: str) -> float:
    return statistics.median(getattr(r, key) for r in rounds)


def table(results: list[Round]) -> str:
    """The Markdown table: the medians of each rate and kind (``sent``: images published
    in a round), and the server CPU per delivery over the Foxglove readers'."""
    lines = [
        "| 1 MB Image | receiver | sent | delivered % | delivered msg/s "
        "| p50 ms | p99 ms | server CPU us/delivery | vs Foxglove | readers' CPU |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for hz in dict.fromkeys(r.hz for r in results):
        by = {k: [r for r in results if r.hz == hz and r.kind == k] for k in KINDS}
        base = _median(by["foxglove"], "cpu_us_per_delivery") if by["foxglove"] else None
        for kind, rounds in by.items():
            if not rounds:
                continue
            cpu = _median(rounds, "cpu_us_per_delivery")
            ratio = f"{cpu / base:.2f}x" if base else "-"
            lines.append(
                f"| {f'{hz} Hz' if hz else 'max rate'}, {rounds[0].readers} readers "
                f"({len(rounds)} rounds) | {LABELS[kind]} | {_median(rounds, 'sent'):,.0f} "
                f"| {_median(rounds, 'delivered_pct'):.1f} | {_median(rounds, 'msg_per_s'):,.0f} "
                f"| {_median(rounds, 'p50_ms'):.1f} | {_median(rounds, 'p99_ms'):.1f} "
                f"| {cpu:,.0f} | {ratio} | {_median(rounds, 'readers_cpu'):.0%} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run every rate and kind; print the Markdown table (``--json``: every round's figures)."""
    from .ros2_bridge import FASTDDS, rclpy_available  # noqa: PLC0415

    parser = argparse.ArgumentParser(prog="python -m benchmarks ros2 --foxglove")
    parser.add_argument("--seconds", type=float, default=5.0, help="timed publishing per round")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of each kind per rate")
    parser.add_argument("--readers", type=int, default=READERS, help="readers of each kind")
    parser.add_argument("--rates", default="30,0", help="comma-separated Hz; 0: as fast as it goes")
    parser.add_argument(
        "--kinds", default=",".join(KINDS), help="comma-separated: " + ",".join(KINDS)
    )
    parser.add_argument("--domain", type=int, default=130 + os.getpid() % 10, help="ROS_DOMAIN_ID")
    parser.add_argument(
        "--fastdds",
        choices=list(FASTDDS),
        default="large-shm",
        help="Fast DDS setup (ros2_bridge.py's FASTDDS); a 1 MB sample outgrows the default "
        "512 KB shared-memory segment",
    )
    parser.add_argument("--json", type=Path, help="write every round's figures here")
    args = parser.parse_args(argv)
    if not rclpy_available():
        print('skipped: rclpy is not importable (pip install "rwt-rosbridge[ros2]")')
        return 0
    rates = [int(x) for x in args.rates.split(",") if x]
    kinds = [k for k in args.kinds.split(",") if k]
    if unknown := set(kinds) - set(KINDS):
        parser.error(f"unknown kinds: {sorted(unknown)}")
    results = asyncio.run(
        run(args.rounds, args.seconds, rates, kinds, args.domain, args.fastdds, args.readers)
    )
    print(table(results))
    if args.json:
        args.json.write_text(json.dumps([asdict(r) for r in results], indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
