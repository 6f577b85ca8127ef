"""The classes of the attack replays about clients that do not read (``benchmarks/attacks.py``):
16 (Foxglove asset fetchers), 17 (a ``png`` subscriber beside one that reads) and 19
(trickling readers, ``benchmarks/trickling_readers.py``).

A client that does not read is a raw socket with a 4 KB kernel receive buffer that
reads nothing after its request, so what the server sends it waits in the server.
"""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import time
from pathlib import Path
from typing import Any

import anyio
import anyio.to_thread
from websockets.asyncio.client import connect
from websockets.typing import Subprotocol

from . import trickling_readers
from .attack_kit import Attack, Context, Outcome
from .rawws import masked_text, stalled_websocket
from .servers import ROOT

__all__ = ["ATTACKS"]

MiB = 1024 * 1024
TIMEOUT_S = 60.0


def _supports(option: str) -> bool:
    """Whether the server's source (``$RWT_BENCH_SRC`` or this checkout's) has ``option``
    (``--memory-budget``: its parameter ``memory_budget`` in ``rwt_cli``)."""
    src = Path(os.environ.get("RWT_BENCH_SRC") or ROOT / "src")
    name = option.removeprefix("--").replace("-", "_")
    return any(name in path.read_text() for path in (src / "rwt_cli").glob("*.py"))


# ---- 16: Foxglove clients that fetch a large asset and never read ---------------------------

ASSET = 10 * MiB
BUDGET = 64 * MiB
FETCHERS = 30
URI = "package://robot_description/meshes/big.stl"


def _assets(work: Path) -> list[str]:
    meshes = work / "packages" / "robot_description" / "meshes"
    meshes.mkdir(parents=True)
    (meshes / "big.stl").write_bytes(os.urandom(ASSET))
    args = ["--no-tf", "--package-path", str(work / "packages")]
    if _supports("--memory-budget"):
        args += ["--memory-budget", str(BUDGET)]
    return args


def _stalled_fetch(port: int) -> socket.socket:
    sock = stalled_websocket(port, "foxglove.sdk.v1", b"serverInfo")
    op = {"op": "fetchAsset", "uri": URI, "requestId": 1}
    sock.sendall(masked_text(json.dumps(op).encode()))
    return sock


async def _fetch(ws_url: str) -> dict[str, Any]:
    """A Foxglove client that reads: the status of its fetch, the bytes or the error."""
    async with connect(
        ws_url,
        subprotocols=[Subprotocol("foxglove.sdk.v1")],
        open_timeout=TIMEOUT_S,
        max_size=None,
    ) as ws:
        await ws.send(json.dumps({"op": "fetchAsset", "uri": URI, "requestId": 7}))
        with anyio.fail_after(TIMEOUT_S):
            while True:
                frame = await ws.recv()
                if isinstance(frame, bytes) and frame[0] == 0x04:  # fetch asset response
                    status = frame[5]
                    (length,) = struct.unpack_from("<I", frame, 6)
                    error = frame[10 : 10 + length].decode()
                    return {
                        "status": status,
                        "error": error[:300],
                        "bytes": len(frame) - 10 - length,
                    }


async def _asset_fetchers(context: Context) -> Outcome:
    port = int(context.ws_url.rsplit(":", 1)[1])
    socks: list[socket.socket] = []
    deadline = time.monotonic() + context.seconds
    try:
        for _ in range(FETCHERS):
            socks.append(await anyio.to_thread.run_sync(_stalled_fetch, port))
        await anyio.sleep(max(0.0, deadline - time.monotonic() - 3))
        reader = await _fetch(context.ws_url)
        await anyio.sleep(max(0.0, deadline - time.monotonic()))
    finally:
        for sock in socks:
            sock.close()
    ok = (reader["status"] == 0 and reader["bytes"] == ASSET) or (
        reader["status"] == 1 and "--memory-budget" in reader["error"]
    )
    return Outcome(
        {"non-reading fetchers": len(socks), "a reading client's fetch then": reader},
        ok,
        "a reading client gets the asset or a refusal naming --memory-budget",
    )


# ---- 17: a png subscriber that does not read beside one that reads --------------------------

PNG_TOPIC = "/png_burst"
PAYLOAD = 32 * 1024
BURSTS = 10
SEND_BUFFER = 16 * MiB  # --send-buffer-limit's default: what the non-reader may hold


class _Tcp(trickling_readers.TcpPeer):
    """A TCP peer that reads whole JSON lines."""

    def __init__(self, port: int, rcvbuf: int | None = None) -> None:
        super().__init__(port, rcvbuf)
        self.sock.settimeout(TIMEOUT_S)
        self.buffer = b""

    def lines(self) -> list[bytes]:
        chunk = self.sock.recv(1 << 20)
        if not chunk:
            raise EOFError("the server closed the connection")
        *lines, self.buffer = (self.buffer + chunk).split(b"\n")
        return lines

    def settle_tagged(self, tag: str) -> None:
        """Until the server answered a call sent now (everything before it is handled)."""
        self.send({"op": "call_service", "service": "/rosapi/get_time", "id": tag})
        while not any(f'"{tag}"'.encode() in line for line in self.lines()):
            pass


def _subscribe_png(peer: _Tcp, tag: str) -> None:
    peer.send(
        {"op": "subscribe", "topic": PNG_TOPIC, "type": "std_msgs/String", "compression": "png"}
    )
    peer.settle_tagged(tag)


def _publish(peer: _Tcp, first: int, count: int) -> None:
    ops = (
        {
            "op": "publish",
            "topic": PNG_TOPIC,
            "msg": {"data": f"{i:08d}{base64.b64encode(os.urandom(PAYLOAD * 3 // 4)).decode()}"},
        }
        for i in range(first, first + count)
    )
    peer.sock.sendall(b"".join(json.dumps(op).encode() for op in ops))


def _read_png(peer: _Tcp, last: int, deadline: float) -> list[int]:
    from rwt_protocol.codecs.png import decode_png  # noqa: PLC0415 (the client's decoder)

    seen: list[int] = []
    peer.sock.settimeout(1.0)
    while (not seen or seen[-1] != last) and time.monotonic() < deadline:
        try:
            lines = peer.lines()
        except TimeoutError:
            continue
        for line in lines:
            frame = json.loads(line)
            if frame.get("op") == "png":
                op = json.loads(decode_png(frame["data"], max_bytes=1 << 20))
                seen.append(int(op["msg"]["data"][:8]))
    return seen


async def _png_readers(context: Context) -> Outcome:
    port = context.tcp_port
    reader = await anyio.to_thread.run_sync(_Tcp, port)
    stalled = await anyio.to_thread.run_sync(lambda: _Tcp(port, rcvbuf=4096))
    publisher = await anyio.to_thread.run_sync(_Tcp, port)
    try:
        await anyio.to_thread.run_sync(_subscribe_png, reader, "r")
        await anyio.to_thread.run_sync(_subscribe_png, stalled, "s")
        publisher.send({"op": "advertise", "topic": PNG_TOPIC, "type": "std_msgs/String"})
        await anyio.to_thread.run_sync(publisher.settle_tagged, "p")
        sizes = [12] * BURSTS + [1000]
        total = sum(sizes)
        deadline = time.monotonic() + context.seconds
        seen: list[list[int]] = []

        async def read() -> None:
            seen.append(await anyio.to_thread.run_sync(_read_png, reader, total - 1, deadline + 20))

        async with anyio.create_task_group() as tg:
            tg.start_soon(read)
            first = 0
            for size in sizes:
                await anyio.to_thread.run_sync(_publish, publisher, first, size)
                first += size
                await anyio.sleep(min(0.5, context.seconds / 40))
        got = seen[0]
        await anyio.sleep(max(0.0, deadline - time.monotonic()))
    finally:
        for peer in (reader, stalled, publisher):
            peer.sock.close()
    return Outcome(
        {
            "published": f"{BURSTS} bursts of 12 and one of 1,000 ({PAYLOAD // 1024} KB each)",
            "the reader got": len(got),
            "in order": got == sorted(got),
            "missing": total - len(set(got)),
        },
        got == list(range(total)),
        "the reading png subscriber got every message, in order",
    )


# ---- 19: trickling readers ------------------------------------------------------------------


async def _stream_baseline(context: Context, seconds: float) -> None:
    """The topic's 10 MB/s without the attackers: what the bystander shares the server with."""
    await anyio.to_thread.run_sync(
        trickling_readers.run_attack, "none", context.tcp_port, seconds, 5.0
    )


async def _trickling(context: Context) -> Outcome:
    result = await anyio.to_thread.run_sync(
        trickling_readers.run_attack, "four", context.tcp_port, context.seconds, 5.0
    )
    return Outcome(
        {
            "reading subscriber's messages": f"{result.messages}/{result.expected}",
            "frozen s": result.frozen_s,
            "frozen share": result.frozen_share,
            "longest gap s": result.longest_gap_s,
        },
        result.frozen_share < 0.05 and result.longest_gap_s < 1.0,
        "the topic frozen under 5 % of the attack, no gap of 1 s (the issue's bound)",
    )


ATTACKS = [
    Attack(
        "16",
        "Foxglove clients fetching a 10 MB asset and never reading",
        _assets,
        _asset_fetchers,
        f"{FETCHERS} fetchers as in the issue, --memory-budget {BUDGET // MiB} MiB "
        "(where the server has it); a reading client fetches 3 s before the end",
        bound=(BUDGET + 32 * MiB, f"D44: --memory-budget {BUDGET // MiB} MiB (+32 MB slack)"),
    ),
    Attack(
        "17",
        "a png subscriber that does not read beside one that reads",
        lambda _: ["--no-tf"],
        _png_readers,
        f"{BURSTS} bursts of 12 messages 0.5 s apart, then one of 1,000, of {PAYLOAD // 1024} KB",
        bound=(
            2 * SEND_BUFFER + 32 * MiB,
            "D45: each png subscriber's outbox within --send-buffer-limit, 2 x 16 MiB "
            "(+32 MB slack)",
        ),
        tcp=True,
    ),
    Attack(
        "19",
        "four trickling readers of a 10 MB/s topic",
        lambda _: ["--no-tf"],
        _trickling,
        "benchmarks/trickling_readers.py's 'four' for 20 s (the issue: 40 s); the baseline "
        "is the same stream without them",
        bound=(
            4 * SEND_BUFFER + 32 * MiB,
            "D24: each reader's --send-buffer-limit, 16 MiB (+32 MB slack)",
        ),
        baseline=_stream_baseline,
        tcp=True,
    ),
]
