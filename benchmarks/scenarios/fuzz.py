"""B18: one million fuzzed frames over WebSocket, TCP and UDP against ``rwt serve``.

Frames come from the fuzz suite's grammar (``tests/fuzz/grammar.py``: every op of
the spec, valid and with hostile fields, JSON and CBOR, raw hostile frames), a
seeded pool cycled in bursts, one fresh connection per burst, round robin over
the transports. After each burst a barrier checks the fuzz invariant
(``tests/fuzz/driver.py``: only status frames, replies of the ops sent, or a
clean close); every ``BYSTANDER_EVERY`` bursts a WebSocket bystander connected
throughout must get its publish back and a ``/rosapi/topics`` answer. Bounded in
frames (``--frames``, default 1,000,000) and time (``MAX_SECONDS``). stdio is
covered by ``tests/fuzz`` (a subprocess has one stdio session).
"""

from __future__ import annotations

import itertools
import json
import random
import time
from typing import Any

import anyio
from tests.fuzz import driver, grammar
from websockets.asyncio.client import ClientConnection, connect

from .common import Metrics, Run

__all__ = ["SETTINGS", "fuzz_run"]

SETTINGS: dict[str, Any] = {"frames": 1_000_000}
"""``--frames`` of ``python -m benchmarks run``: frames to send (the smoke form scales it)."""
MAX_SECONDS = 3600.0
SMOKE_FRAMES = 1500  # --smoke: a few seconds
BURST = 100
POOL = 5000
POOL_FRAME_BYTES = 16_384  # larger hostile frames are the pytest suite's; here, rate
BYSTANDER_EVERY = 50
TIMEOUT_S = 10.0
SEED = 18


def _pool(seed: int) -> list[tuple[bytes, bool]]:
    rng = random.Random(seed)
    pool: list[tuple[bytes, bool]] = []
    while len(pool) < POOL:
        frame = grammar.fuzz_frame(rng)
        if len(frame[0]) <= POOL_FRAME_BYTES:
            pool.append(frame)
    return pool


def _ports(run: Run) -> dict[str, int]:
    """The TCP and UDP ports from the server's further ``listening on`` lines."""
    ports = {"websocket": run.port}
    stdout = run.server.process.stdout
    assert stdout is not None
    while len(ports) < 3:
        url = stdout.readline().decode().strip().removeprefix("listening on ")
        scheme, _, rest = url.partition("://")
        if not rest:
            raise RuntimeError(f"unexpected server line {url!r}")
        ports[scheme] = int(rest.rsplit(":", 1)[1])
    return ports


async def _bystander(ws: ClientConnection, tag: str) -> None:
    await ws.send(json.dumps({"op": "publish", "topic": "/bystander", "msg": {"data": tag}}))
    await ws.send(json.dumps({"op": "call_service", "service": "/rosapi/topics", "id": tag}))
    got = set()
    with anyio.fail_after(TIMEOUT_S):
        while len(got) < 2:
            message = json.loads(await ws.recv())
            if message.get("op") == "publish" and message.get("msg") == {"data": tag}:
                got.add("publish")
            if message.get("op") == "service_response" and message.get("id") == tag:
                if message.get("result") is not True:
                    raise driver.Violation(f"bystander: /rosapi/topics failed: {message}")
                got.add("rosapi")


async def _burst(
    transport: str, ports: dict[str, int], frames: list[tuple[bytes, bool]], tag: str
) -> None:
    if transport == "ws":
        async with connect(f"ws://127.0.0.1:{ports['websocket']}", max_size=None) as ws:
            await driver.exchange(driver.ws_wire(ws), frames, tag, TIMEOUT_S)
    elif transport == "tcp":
        async with await anyio.connect_tcp("127.0.0.1", ports["tcp"]) as stream:
            await driver.exchange(
                driver.stream_wire(stream, eof_after=True), frames, tag, TIMEOUT_S
            )
    else:
        async with await anyio.create_connected_udp_socket("127.0.0.1", ports["udp"]) as sock:
            wire = driver.udp_wire(sock)
            await driver.udp_handshake(wire)
            await driver.exchange(wire, frames, tag, TIMEOUT_S)


async def _campaign(run: Run, ports: dict[str, int], total: int, log: list[str]) -> tuple[int, int]:
    pool = _pool(SEED)
    cycle = itertools.cycle(pool)
    transports = itertools.cycle(("ws", "tcp", "udp"))
    sent = violations = 0
    deadline = time.monotonic() + MAX_SECONDS
    bystander = await connect(f"ws://127.0.0.1:{ports['websocket']}")
    try:
        for op in (
            {"op": "subscribe", "topic": "/bystander", "type": "std_msgs/String"},
            {"op": "advertise", "topic": "/bystander", "type": "std_msgs/String"},
        ):
            await bystander.send(json.dumps(op))
        for index in itertools.count():
            if sent >= total or time.monotonic() > deadline:
                break
            frames = [next(cycle) for _ in range(min(BURST, total - sent))]
            transport = next(transports)
            try:
                await _burst(transport, ports, frames, f"b{index}")
                if index % BYSTANDER_EVERY == 0:
                    await _bystander(bystander, f"b{index}")
            except Exception as exc:
                violations += 1
                if len(log) < 20:
                    log.append(f"{transport} burst {index}: {exc!r:.300}")
                if not run.server.alive():
                    log.append("the server died")
                    break
            sent += len(frames)
        if run.server.alive():
            try:
                await _bystander(bystander, "final")
            except Exception as exc:
                violations += 1
                log.append(f"final bystander check: {exc!r:.300}")
    finally:
        await bystander.close()
    return sent, violations


def fuzz_run(run: Run) -> Metrics:
    """Send the fuzzed frames; raise when an invariant broke (the run is marked failed)."""
    ports = _ports(run)
    total = SETTINGS["frames"] if run.scale >= 1 else min(SETTINGS["frames"], SMOKE_FRAMES)
    before = run.server.stats()
    log: list[str] = []
    started = time.perf_counter()
    sent, violations = anyio.run(_campaign, run, ports, total, log)
    elapsed = time.perf_counter() - started
    after = run.server.stats() if run.server.alive() else before
    if violations or not run.server.alive():
        raise RuntimeError(f"{violations} violation(s): " + "; ".join(log))
    return {
        "frames": float(sent),
        "frames_per_s": sent / elapsed,
        "violations": float(violations),
        "rss_before_mb": before.rss_bytes / 1e6,
        "rss_after_mb": after.rss_bytes / 1e6,
        "server_cpu_pct": 100.0 * (after.cpu_s - before.cpu_s) / elapsed,
    }
