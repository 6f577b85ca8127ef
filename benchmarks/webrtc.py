"""W1: the ``rosbridge`` data channel's throughput against the WebSocket, on loopback.

One ``rwt serve --webrtc`` subprocess a stack (``--webrtc-stack aiortc``, and
``native`` where libdatachannel-py imports, D51); in this process a publisher on
a raw WebSocket (``websockets``) and a subscriber on the transport measured: a
WebSocket (``ws``), the ``rosbridge`` data channel on aiortc (``webrtc``, rwt's
client, aiortc, against the aiortc server), or on libdatachannel
(``webrtc-native``: a libdatachannel peer of this process, decoding each
message as rwt's client does, against the native server). ``std_msgs/String``
of 100 B and of 100 KB go through as fast as the subscriber takes them: the
publisher keeps at most a window of messages ahead of what the subscriber got,
so nothing is dropped and the rate is the one the path sustains. Beside them,
``aiortc`` and ``native`` are two peers of that stack in this process alone,
sending the same payloads on a data channel with nothing else (the cost of the
stack's SCTP, DTLS and ICE, no rosbridge): the bare figure of the WebRTC path,
as the bare relay is the WebSocket's.

Reported per variant: messages/s and MB/s at the subscriber, the server's CPU
per message (``/proc``), this process's CPU per message (the client side: the
publisher and the subscriber, the WebRTC stack for ``webrtc``), and, with the
runs alternating between the transports, the webrtc/ws ratios of one run.

    python -m benchmarks.webrtc [--runs 3] [--smoke]

Prints a table and writes ``benchmarks/results/webrtc.json`` (not with --smoke).
Needs aiortc (``pip install "rwt-rosbridge[webrtc]"``) and an address besides
loopback (aiortc offers no 127.0.0.1 candidate, docs/webrtc.md).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import anyio
import msgspec
from websockets.asyncio.client import connect as ws_connect

import rwt
from rwt_transports.webrtc.native import Inflow, NativeDataChannel, native_missing

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

RESULTS = Path(__file__).parent / "results" / "webrtc.json"
SRC = Path(__file__).resolve().parents[1] / "src"
MB = 1_000_000
TICKS = os.sysconf("SC_CLK_TCK")
LIMIT_S = 120.0  # a bound on a hung run, not a measurement


@dataclass(frozen=True)
class Size:
    """One payload: its name, bytes of ``data``, messages a run, messages in flight at most."""

    name: str
    data_bytes: int
    count: int
    window: int


SIZES = (Size("100 B", 100, 20_000, 200), Size("100 KB", 100_000, 400, 16))


@dataclass
class Run:
    """One variant's figures in one run."""

    messages: int
    seconds: float
    server_cpu_s: float
    client_cpu_s: float
    payload: int

    @property
    def rate(self) -> float:
        return self.messages / self.seconds

    @property
    def mb_s(self) -> float:
        return self.messages * self.payload / self.seconds / MB

    @property
    def server_us(self) -> float:
        return self.server_cpu_s / self.messages * 1e6

    @property
    def client_us(self) -> float:
        return self.client_cpu_s / self.messages * 1e6


@dataclass
class Variant:
    transport: str
    size: Size
    runs: list[Run] = field(default_factory=list)

    def median(self, attribute: str) -> float:
        return statistics.median(getattr(run, attribute) for run in self.runs)


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime + stime


def _publish_frame(number: int, payload: str) -> str:
    msg = {"data": f"{number:08d}{payload}"}
    return msgspec.json.encode({"op": "publish", "topic": "/w1", "msg": msg}).decode()


@dataclass
class Counter:
    """The subscriber's count of messages, and its wake-ups."""

    target: int
    got: int = 0
    moved: anyio.Event = field(default_factory=anyio.Event)
    done: anyio.Event = field(default_factory=anyio.Event)

    def arrived(self, _: object = None) -> None:
        self.got += 1
        self.moved.set()
        if self.got == self.target:
            self.done.set()


async def through_server(transport: str, size: Size, ws_url: str, server_pid: int) -> Run:
    """Publish ``size.count`` messages over a WebSocket to a subscriber on ``transport``."""
    counter = Counter(size.count)
    async with contextlib.AsyncExitStack() as stack:
        if transport == "webrtc-native":
            base = ws_url.replace("ws://", "http://")
            await stack.enter_async_context(native_subscriber(base, counter))
        else:
            url = ws_url if transport == "ws" else ws_url.replace("ws://", "webrtc+http://")
            ros = await stack.enter_async_context(
                rwt.Ros(url if transport == "ws" else url + "/webrtc", reconnect=False)
            )
            await rwt.Topic(ros, "/w1", "std_msgs/String").subscribe(counter.arrived)
            await ros.get_topics()  # the subscription is in place
        return await _publish(size, ws_url, server_pid, counter)


async def _publish(size: Size, ws_url: str, server_pid: int, counter: Counter) -> Run:
    """Publish ``size.count`` messages, at most ``size.window`` ahead of ``counter``."""
    payload = "x" * (size.data_bytes - 8)
    async with ws_connect(ws_url, max_size=None) as pub:
        await pub.send(
            msgspec.json.encode(
                {"op": "advertise", "topic": "/w1", "type": "std_msgs/String"}
            ).decode()
        )
        frames = [_publish_frame(n, payload) for n in range(size.count)]
        cpu, server = time.process_time(), _cpu_s(server_pid)
        start = time.perf_counter()
        with anyio.fail_after(LIMIT_S):
            for number, frame in enumerate(frames):
                while number - counter.got >= size.window:
                    counter.moved = anyio.Event()
                    await counter.moved.wait()
                await pub.send(frame)
            await counter.done.wait()
        seconds = time.perf_counter() - start
        client, server = time.process_time() - cpu, _cpu_s(server_pid) - server
    return Run(counter.got, seconds, server, client, size.data_bytes)


@contextlib.asynccontextmanager
async def native_subscriber(base: str, counter: Counter) -> AsyncIterator[None]:
    """A libdatachannel peer subscribed to ``/w1`` on ``base``/webrtc; closed on exit.

    Each message hops onto the loop (``NativeDataChannel``, as the server's do) and
    is decoded there, ``fragment`` ops joined, as rwt's client does.
    """
    import httpx  # noqa: PLC0415 (the test extra's)

    ldc, loop = _ldc(), asyncio.get_running_loop()
    pc = ldc.PeerConnection(ldc.Configuration())
    opened, answered = anyio.Event(), anyio.Event()

    parts: list[str] = []

    def on_message(raw: str | bytes) -> None:
        message = msgspec.json.decode(raw)
        op = message.get("op")
        if op == "fragment":  # over 64 KiB: the data channel's fragments, joined
            parts.append(message["data"])
            if message["num"] < message["total"] - 1:
                return
            message = msgspec.json.decode("".join(parts))
            parts.clear()
            op = message.get("op")
        if op == "publish":
            counter.arrived()
        elif op == "service_response":
            answered.set()

    # the server's face of a libdatachannel channel: its hop onto the loop, batched
    channel = NativeDataChannel(
        pc.create_data_channel("rosbridge"), loop, Inflow(1 << 40, lambda: 0), 1 << 30
    )
    channel.on("open", opened.set)
    channel.on("message", on_message)
    channel.listen()
    try:
        with anyio.fail_after(LIMIT_S):
            await gathered(ldc, pc)
            async with httpx.AsyncClient(base_url=base) as http:
                reply = await http.post(
                    "/webrtc",
                    content=str(pc.local_description()),
                    headers={"Content-Type": "application/sdp"},
                )
            assert reply.status_code == 201, reply.text
            pc.set_remote_description(ldc.Description(reply.text, ldc.Description.Type.Answer))
            await opened.wait()
            for op in (
                {"op": "subscribe", "topic": "/w1", "type": "std_msgs/String"},
                {"op": "call_service", "service": "/rosapi/topics", "id": "barrier"},
            ):
                channel.send(msgspec.json.encode(op).decode())
            await answered.wait()  # the subscription is in place
        yield
    finally:
        await anyio.to_thread.run_sync(pc.close)


def _ldc() -> Any:
    import libdatachannel  # noqa: PLC0415 (optional: Python 3.12+, D51)

    return libdatachannel


async def gathered(ldc: Any, pc: Any) -> None:
    """Wait until ``pc`` gathered its candidates: polled, not a callback, as the server
    does (rwt_transports.webrtc.native: a callback could wait for the GIL while
    ``set_remote_description`` holds it)."""
    complete = ldc.PeerConnection.GatheringState.Complete
    while pc.gathering_state() != complete:  # noqa: ASYNC110 (the docstring)
        await anyio.sleep(0.005)


async def native_alone(size: Size) -> Run:
    """The same payloads between two libdatachannel peers of this process, nothing else."""
    ldc, loop = _ldc(), asyncio.get_running_loop()
    offerer, answerer = ldc.PeerConnection(), ldc.PeerConnection()
    counter = Counter(size.count)
    opened = anyio.Event()
    kept: list[Any] = []  # the answerer's channel lives as long as the run

    def on_channel(channel: Any) -> None:
        kept.append(channel)
        channel.on_message(lambda _: loop.call_soon_threadsafe(counter.arrived))

    answerer.on_data_channel(on_channel)
    sending = offerer.create_data_channel("bare")
    sending.on_open(lambda: loop.call_soon_threadsafe(opened.set))
    try:
        with anyio.fail_after(LIMIT_S):
            await gathered(ldc, offerer)
            answerer.set_remote_description(offerer.local_description())
            await gathered(ldc, answerer)
            offerer.set_remote_description(answerer.local_description())
            await opened.wait()
            frames = [_publish_frame(n, "x" * (size.data_bytes - 8)) for n in range(size.count)]
            cpu, start = time.process_time(), time.perf_counter()
            for number, frame in enumerate(frames):
                while number - counter.got >= size.window:
                    counter.moved = anyio.Event()
                    await counter.moved.wait()
                sending.send(frame)
            await counter.done.wait()
        seconds, client = time.perf_counter() - start, time.process_time() - cpu
    finally:
        await anyio.to_thread.run_sync(offerer.close)
        await anyio.to_thread.run_sync(answerer.close)
    return Run(counter.got, seconds, 0.0, client, size.data_bytes)


async def aiortc_alone(size: Size) -> Run:
    """The same payloads between two aiortc peers of this process, nothing else."""
    from aiortc import RTCConfiguration, RTCPeerConnection  # noqa: PLC0415 (optional)

    offerer = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    answerer = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    sending = offerer.createDataChannel("bare")
    got = 0
    moved, done, opened = anyio.Event(), anyio.Event(), anyio.Event()

    def on_channel(channel: object) -> None:
        def on_message(_: object) -> None:
            nonlocal got
            got += 1
            moved.set()
            if got == size.count:
                done.set()

        channel.on("message", on_message)  # type: ignore[attr-defined]

    answerer.on("datachannel", on_channel)
    sending.on("open", opened.set)
    try:
        await offerer.setLocalDescription(await offerer.createOffer())
        await answerer.setRemoteDescription(offerer.localDescription)
        await answerer.setLocalDescription(await answerer.createAnswer())
        await offerer.setRemoteDescription(answerer.localDescription)
        with anyio.fail_after(LIMIT_S):
            await opened.wait()
            frames = [_publish_frame(n, "x" * (size.data_bytes - 8)) for n in range(size.count)]
            cpu, start = time.process_time(), time.perf_counter()
            for number, frame in enumerate(frames):
                while number - got >= size.window:
                    moved = anyio.Event()
                    await moved.wait()
                sending.send(frame)
            await done.wait()
        seconds, client = time.perf_counter() - start, time.process_time() - cpu
    finally:
        await offerer.close()
        await answerer.close()
    return Run(got, seconds, 0.0, client, size.data_bytes)


def _serve(stack: str) -> tuple[subprocess.Popen[str], str]:
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    command = [sys.executable, "-m", "rwt", "serve", "--port", "0", "--webrtc"]
    command += ["--webrtc-stack", stack]
    process = subprocess.Popen(
        [*command, "--log-level", "error"], env=env, stdout=subprocess.PIPE, text=True
    )
    assert process.stdout is not None
    line = process.stdout.readline()
    assert line.startswith("listening on "), line
    return process, line.removeprefix("listening on ").strip()


async def measure(runs: int, sizes: tuple[Size, ...]) -> list[Variant]:
    paths = ("ws", "webrtc", "aiortc")
    if native_missing() is None:  # the native stack's rows beside (D51)
        paths = ("ws", "webrtc", "webrtc-native", "aiortc", "native")
    else:
        print(f"no native rows: {native_missing()}", file=sys.stderr)
    variants = [Variant(t, s) for s in sizes for t in paths]
    servers = {stack: _serve(stack) for stack in ("aiortc", "native") if stack in paths}
    try:
        for _ in range(runs):  # alternating: every transport sees the same machine state
            for variant in variants:
                variant.runs.append(await _one_run(variant, servers))
                print(
                    f"{variant.transport} {variant.size.name}: {variant.runs[-1].rate:,.0f} msg/s",
                    file=sys.stderr,
                )
    finally:
        for process, _ in servers.values():
            process.terminate()
            process.wait(timeout=10)
    return variants


async def _one_run(variant: Variant, servers: dict[str, tuple[subprocess.Popen[str], str]]) -> Run:
    if variant.transport == "aiortc":
        return await aiortc_alone(variant.size)
    if variant.transport == "native":
        return await native_alone(variant.size)
    process, url = servers["native" if variant.transport == "webrtc-native" else "aiortc"]
    return await through_server(variant.transport, variant.size, url, process.pid)


def table(variants: list[Variant]) -> str:
    lines = [
        "| size | path | messages/s | MB/s | server CPU per message"
        " | client CPU per message | webrtc/ws (one run, median) |",
        "|---|---|---|---|---|---|---|",
    ]
    for variant in variants:
        ratio = ""
        if variant.transport.startswith("webrtc"):
            ws = next(v for v in variants if v.size == variant.size and v.transport == "ws")
            ratios = [w.rate / s.rate for w, s in zip(variant.runs, ws.runs, strict=True)]
            ratio = f"{statistics.median(ratios):.2f}x"
        server = (
            ""
            if variant.transport in ("aiortc", "native")
            else f"{variant.median('server_us'):,.0f} us"
        )
        lines.append(
            f"| {variant.size.name} | {variant.transport} | {variant.median('rate'):,.0f} "
            f"| {variant.median('mb_s'):.1f} | {server} | {variant.median('client_us'):,.0f} us "
            f"| {ratio} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--smoke", action="store_true", help="one run of tiny counts")
    args = parser.parse_args()
    sizes = SIZES
    if args.smoke:
        sizes = tuple(Size(s.name, s.data_bytes, max(s.count // 100, 4), s.window) for s in SIZES)
    variants = anyio.run(measure, 1 if args.smoke else args.runs, sizes)
    print(table(variants))
    if not args.smoke:
        document = {
            "runs": args.runs,
            "variants": [
                {
                    "size": v.size.name,
                    "path": v.transport,
                    "runs": [
                        {
                            "msg_s": r.rate,
                            "mb_s": r.mb_s,
                            "server_us": r.server_us,
                            "client_us": r.client_us,
                        }
                        for r in v.runs
                    ],
                }
                for v in variants
            ],
        }
        RESULTS.write_text(json.dumps(document, indent=1) + "\n")


if __name__ == "__main__":
    main()
