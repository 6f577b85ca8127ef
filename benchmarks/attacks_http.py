"""The classes of the attack replays about the HTTP API (``benchmarks/attacks.py``, D59):
30 (event streams' CPU against WebSocket subscribers'), 31 (one host's event streams) and
32 (clients fetching the OpenAPI document of a 5,000-topic graph).

The readers are ``benchmarks/http_streams.py`` in a process of their own, reading and
dropping, so that a WebSocket subscriber and an event stream cost the reader the same;
the topic is published by a rosbridge client at ``RATE_HZ``.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import anyio
import anyio.to_thread
from websockets.asyncio.client import ClientConnection, connect

from .attack_kit import OTHER_HOST, Attack, Context, Outcome
from .servers import ROOT, proc_stats

__all__ = ["ATTACKS"]

TOPIC = "/tick"
RATE_HZ = 50.0
PAYLOAD = "x" * 100
READERS = 500
ONE_HOST = 2000
HOST_SHARE = 64  # --max-connections-per-host's default
TOPICS = 5000
FETCHERS = 4
TIMEOUT_S = 60.0
_TYPES = (
    "std_msgs/msg/String",
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/Twist",
    "sensor_msgs/msg/Imu",
    "std_msgs/msg/Int32",
)
_measured: dict[int, dict[str, Any]] = {}  # a context's baseline figures, for its attack


def _port(context: Context) -> int:
    return int(context.ws_url.rsplit(":", 1)[1])


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


# ---- the topic and its readers ------------------------------------------------------------


class _Publisher:
    """``TOPIC`` published at ``RATE_HZ`` by a rosbridge client, paced by absolute deadlines."""

    def __init__(self) -> None:
        self.sent = 0
        self.started = anyio.Event()

    async def run(self, ws_url: str) -> None:
        async with connect(ws_url, open_timeout=TIMEOUT_S, max_size=None) as ws:
            advertise = {"op": "advertise", "topic": TOPIC, "type": "std_msgs/msg/String"}
            await ws.send(json.dumps(advertise))
            start = time.monotonic()
            while True:
                op = {"op": "publish", "topic": TOPIC, "msg": {"data": f"{PAYLOAD}{self.sent}"}}
                await ws.send(json.dumps(op))
                self.sent += 1
                self.started.set()
                await anyio.sleep(max(0.0, start + self.sent / RATE_HZ - time.monotonic()))


async def _start_publisher(context: Context) -> _Publisher:
    publisher = _Publisher()
    tg = await context.stack.enter_async_context(anyio.create_task_group())
    context.stack.callback(tg.cancel_scope.cancel)  # before the group's exit waits for it
    tg.start_soon(publisher.run, context.ws_url)
    with anyio.fail_after(TIMEOUT_S):
        await publisher.started.wait()
    return publisher


class _Readers:
    """``benchmarks/http_streams.py`` with ``count`` readers of ``kind``, in its own process."""

    def __init__(self, context: Context, kind: str, count: int, host: str = "127.0.0.1") -> None:
        command = [
            sys.executable,
            "-m",
            "benchmarks.http_streams",
            str(_port(context)),
            "--kind",
            kind,
            "--count",
            str(count),
            "--host",
            host,
            "--topic",
            TOPIC,
        ]
        self.process = subprocess.Popen(
            command,
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )

    def ready(self) -> dict[str, Any]:
        """Wait until every reader is open: ``{"ready": N, "statuses": {...}}``."""
        assert self.process.stdout is not None
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError("the readers' process ended before it was ready")
        found: dict[str, Any] = json.loads(line)
        return found

    def stop(self) -> dict[str, Any]:
        """Stop reading: ``{"messages": M, "bytes": B, "open": K}``."""
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.send_signal(signal.SIGTERM)
        line = self.process.stdout.readline()
        self.process.stdin.close()
        self.process.wait(TIMEOUT_S)
        self.process.stdout.close()
        found: dict[str, Any] = json.loads(line)
        return found


def _first_message_s(port: int, kind: str, host: str) -> float | None:
    """Seconds from a new reader's request to its first message (None: refused, or none
    within ``TIMEOUT_S``)."""
    start = time.monotonic()
    try:
        sock = socket.create_connection(("127.0.0.1", port), TIMEOUT_S, (host, 0))
    except OSError:
        return None
    try:
        if kind == "ws":
            from .http_streams import UPGRADE, _masked  # noqa: PLC0415

            sock.sendall(UPGRADE)
            op = {"op": "subscribe", "topic": TOPIC, "type": "std_msgs/msg/String"}
            sock.sendall(_masked(json.dumps(op).encode()))
            marker = b'"op":"publish"'
        else:
            sock.sendall(f"GET /api/topics{TOPIC}/events HTTP/1.1\r\nHost: x\r\n\r\n".encode())
            marker = b"data: "
        data = b""
        while marker not in data:
            chunk = sock.recv(65536)
            if not chunk:
                return None
            data = data[-64:] + chunk
        return time.monotonic() - start
    except OSError:  # a timeout (TIMEOUT_S), a reset
        return None
    finally:
        sock.close()


async def _readers_phase(
    context: Context, kind: str, publisher: _Publisher, seconds: float
) -> dict[str, Any]:
    """``READERS`` readers of ``kind`` for ``seconds``: the server's CPU meanwhile (per
    delivery due), what the readers got, and a newcomer's wait for its first message."""
    readers = _Readers(context, kind, READERS)
    before_sent = publisher.sent
    opened = await anyio.to_thread.run_sync(readers.ready)
    await anyio.sleep(1.0)  # what the first readers missed while the others opened, sent
    start, cpu, sent = time.monotonic(), proc_stats(context.pid).cpu_s, publisher.sent
    await anyio.sleep(seconds)
    spent, elapsed = proc_stats(context.pid).cpu_s - cpu, time.monotonic() - start
    window = (publisher.sent - sent) * opened["ready"]  # deliveries due in the window
    newcomer = await anyio.to_thread.run_sync(_first_message_s, _port(context), kind, OTHER_HOST)
    got = await anyio.to_thread.run_sync(readers.stop)
    expected = (publisher.sent - before_sent) * opened["ready"]
    return {
        "readers": opened["ready"],
        "statuses": opened["statuses"],
        "published per s": round((publisher.sent - sent) / elapsed, 1),
        "server cores": round(spent / elapsed, 3),
        "server CPU us per delivery": round(spent / max(1, window) * 1e6, 1),
        "delivered": round(got["messages"] / max(1, expected), 3),
        "a newcomer's first message ms": None if newcomer is None else round(newcomer * 1000, 1),
        "load average": _load(),
    }


# ---- 30: event streams against WebSocket subscribers ---------------------------------------

ROUNDS = 2
"""Rounds of (WebSocket subscribers, event streams), each ``context.seconds / ROUNDS / 2``
long: the medians of alternating phases, as the machine's other load comes and goes."""


async def _setup_topic(context: Context) -> None:
    _measured[id(context)] = {"publisher": await _start_publisher(context)}


async def _streams(context: Context) -> Outcome:
    publisher = _measured.pop(id(context))["publisher"]
    phases: dict[str, list[dict[str, Any]]] = {"ws": [], "sse": []}
    seconds = context.seconds / ROUNDS / 2
    for _ in range(ROUNDS):
        for kind, done in phases.items():
            done.append(await _readers_phase(context, kind, publisher, seconds))
    cost = {
        kind: statistics.median(p["server CPU us per delivery"] for p in done)
        for kind, done in phases.items()
    }
    sse = phases["sse"]
    return Outcome(
        {
            "server CPU us per delivery, median": cost,
            "sse/ws": round(cost["sse"] / max(1e-9, cost["ws"]), 2),
            "phases": phases,
        },
        all(p["readers"] == READERS for p in sse)
        and all(p["a newcomer's first message ms"] is not None for p in sse),
        f"all {READERS} streams admitted each round, a newcomer's stream served",
    )


# ---- 31: one host's event streams -----------------------------------------------------------


async def _one_host(context: Context) -> Outcome:
    readers = _Readers(context, "sse", ONE_HOST)
    opened = await anyio.to_thread.run_sync(readers.ready)
    other = await anyio.to_thread.run_sync(_first_message_s, _port(context), "sse", OTHER_HOST)
    await anyio.sleep(max(0.0, context.seconds - 1))
    got = await anyio.to_thread.run_sync(readers.stop)
    statuses = {int(k): v for k, v in opened["statuses"].items()}
    return Outcome(
        {
            "streams asked from one host": ONE_HOST,
            "answered by status": statuses,
            "messages the admitted got": got["messages"],
            "another host's first message ms": None if other is None else round(other * 1000, 1),
            "load average": _load(),
        },
        statuses.get(200, 0) <= HOST_SHARE
        and statuses.get(200, 0) + statuses.get(503, 0) == ONE_HOST
        and other is not None,
        f"at most {HOST_SHARE} streams of the host admitted, the rest 503; another host served",
    )


# ---- 32: clients fetching the OpenAPI document of a 5,000-topic graph ------------------------


async def _advertiser(ws: ClientConnection, names: list[str]) -> None:
    for n, name in enumerate(names):
        op = {"op": "advertise", "topic": name, "type": _TYPES[n % len(_TYPES)]}
        await ws.send(json.dumps(op))
    call = {"op": "call_service", "service": "/rosapi/get_time", "id": "done"}
    await ws.send(json.dumps(call))
    while "done" not in str(await ws.recv()):  # every advertise before it was handled
        pass


async def _big_graph(context: Context) -> None:
    per = 1000  # --max-advertisements' default
    for start in range(0, TOPICS, per):
        ws = await context.stack.enter_async_context(
            connect(context.ws_url, open_timeout=TIMEOUT_S, max_size=None)
        )
        await _advertiser(ws, [f"/robot{n // 100}/topic{n}" for n in range(start, start + per)])


def _fetch(port: int) -> tuple[int, int, float]:
    """One ``GET /openapi.json``: its status, its bytes and its time (s)."""
    start = time.monotonic()
    with socket.create_connection(("127.0.0.1", port), TIMEOUT_S) as sock:
        sock.sendall(b"GET /openapi.json HTTP/1.1\r\nHost: x\r\n\r\n")
        size, status = 0, 0
        while chunk := sock.recv(1 << 20):
            if not size:
                status = int(chunk.split(b" ", 2)[1])
            size += len(chunk)
    return status, size, time.monotonic() - start


async def _document_fetchers(context: Context) -> Outcome:
    port, deadline = _port(context), time.monotonic() + context.seconds
    statuses: Counter[int] = Counter()
    times: list[float] = []
    sizes: list[int] = []
    lock = threading.Lock()

    def fetcher() -> None:
        while time.monotonic() < deadline:
            status, size, took = _fetch(port)
            with lock:
                statuses[status] += 1
                if status == 200:
                    times.append(took)
                    sizes.append(size)
            if status == 429:
                time.sleep(1.0)  # its Retry-After

    async with anyio.create_task_group() as tg:
        for _ in range(FETCHERS):
            tg.start_soon(anyio.to_thread.run_sync, fetcher)
    return Outcome(
        {
            "fetches by status": dict(statuses),
            "document MB": round(max(sizes, default=0) / 1e6, 1),
            "fetch s p50": round(statistics.median(times), 3) if times else None,
            "load average": _load(),
        },
        statuses.get(200, 0) > 0 and set(statuses) <= {200, 429},
        "every fetch answered: the document (200) or the host's bound (429, Retry-After)",
    )


def _serve(extra: list[str]) -> Callable[[Path], list[str]]:
    return lambda _work: ["--no-tf", *extra]


async def _publishing(context: Context) -> None:
    await _start_publisher(context)


ATTACKS = [
    Attack(
        "30",
        "500 event streams of a 50 msg/s topic against 500 WebSocket subscribers",
        _serve(["--max-connections-per-host", "1000"]),
        _streams,
        f"{READERS} of each, {ROUNDS} rounds of each kind for 5 s, from one host under "
        "--max-connections-per-host 1000 (the cost measured, not the share)",
        setup=_setup_topic,
    ),
    Attack(
        "31",
        "2,000 event streams from one host",
        _serve([]),
        _one_host,
        f"{ONE_HOST} streams asked one after another as in the campaign, held 10 s",
        setup=_publishing,
        seconds=10.0,
    ),
    Attack(
        "32",
        "four clients fetching /openapi.json of a 5,000-topic graph",
        _serve([]),
        _document_fetchers,
        f"{FETCHERS} fetchers from one host for 20 s, {TOPICS} topics of 5 types "
        "advertised by 5 rosbridge clients",
        setup=_big_graph,
    ),
]
