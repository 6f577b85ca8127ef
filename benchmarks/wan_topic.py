"""A 1 kHz topic to a browser behind a WAN link: the rosbridge data channel against the WebSocket.

The robot (an in-process ``RosbridgeServer`` with ``--webrtc``, publishing
``std_msgs/String`` at ``--rate`` Hz whose data is its send time) and the
browser (one subscriber per transport, run one after the other) are in two
network namespaces joined by benchmarks/wanlink.py (30 ms +- 10 ms each way, 2 %
loss, 15 Mbit/s by default). Per transport: messages delivered a second (the
topic's rate when it keeps up), messages the server dropped for the session
(its slow-consumer rule, D24), the age of each message when it arrived (receive
time - send time, the same clock: one machine) at p50 and p99, and the longest
stall (the longest time between two messages, where 1 ms is expected; a lost
packet on a reliable, ordered transport stalls everything behind it until its
retransmission arrives).

Transports: ``websocket`` (TCP), ``webrtc`` (the ``rosbridge`` data channel,
reliable and ordered: SCTP over DTLS over UDP), and ``video``: the robot's 30 Hz
640x480 camera (``CAMERA``) played as a VP8 video track (docs/webrtc.md), whose
figures are decoded frames a second and the longest stall (a frame carries no send
time). A message transport is a function from (server address, topic) to an async
iterator of raw messages in ``TRANSPORTS``: the lossy data channel gets its row by
adding its client there.

Run (root, network namespaces; a few seconds a transport)::

    nice -n 10 python -m benchmarks.wan_topic --duration 15 [--transport webrtc ...]

Results: a table on stdout and ``benchmarks/results/wan_topic.json``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Callable
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

import anyio

from benchmarks.wanlink import LinkProfile, WanLink

ROBOT_ADDR = "198.18.5.1"
BROWSER_ADDR = "198.18.5.2"
PORT = 9090
TOPIC = "/wan_clock"
WARMUP_S = 2.0
"""Seconds of each run left out of the figures (connecting, the first window)."""

CAMERA = "/wan_camera"
CAMERA_HZ = 30.0
CONNECT_BOUND_S = 60.0
"""Longest wait for the first message: a failure bound, not a measurement."""

RESULTS = Path(__file__).parent / "results" / "wan_topic.json"
REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": f"{REPO / 'src'}:{REPO}", "PYTHONUNBUFFERED": "1"}

Transport = Callable[[str, str], AsyncIterator[str | bytes]]


async def _websocket(base: str, topic: str) -> AsyncIterator[str | bytes]:
    import websockets  # noqa: PLC0415 (the browser process only)

    async with websockets.connect(f"ws://{base}", max_size=None) as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": topic, "type": "std_msgs/String"}))
        async for raw in ws:
            yield raw


async def _webrtc(base: str, topic: str) -> AsyncIterator[str | bytes]:
    import httpx  # noqa: PLC0415 (the browser process only)
    from aiortc import (  # noqa: PLC0415
        RTCConfiguration,
        RTCPeerConnection,
        RTCSessionDescription,
    )

    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    channel = pc.createDataChannel("rosbridge")
    inbox: list[str | bytes] = []
    arrived = anyio.Event()
    opened = anyio.Event()

    def on_message(message: str | bytes) -> None:
        inbox.append(message)
        arrived.set()

    channel.on("open", opened.set)
    channel.on("message", on_message)
    try:
        await pc.setLocalDescription(await pc.createOffer())
        async with httpx.AsyncClient() as http:
            reply = await http.post(
                f"http://{base}/webrtc",
                content=pc.localDescription.sdp,
                headers={"Content-Type": "application/sdp"},
            )
        reply.raise_for_status()
        await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
        with anyio.fail_after(20):
            await opened.wait()
        channel.send(json.dumps({"op": "subscribe", "topic": topic, "type": "std_msgs/String"}))
        while True:
            await arrived.wait()
            arrived = anyio.Event()
            batch, inbox[:] = inbox[:], []
            for message in batch:
                yield message
    finally:
        await pc.close()


TRANSPORTS: dict[str, Transport] = {"websocket": _websocket, "webrtc": _webrtc}
"""The browser's transports by name; the lossy channel and video tracks add theirs here."""


async def browse(transport: str, duration: float) -> dict[str, Any]:
    """Subscribe over ``transport`` for ``duration`` s from its first message; the figures
    after the warm-up (a slow connection on a busy machine shortens no run)."""
    ages: list[float] = []
    arrivals: list[float] = []
    start = 0.0
    cpu, wall = time.process_time(), time.monotonic()
    with anyio.move_on_after(CONNECT_BOUND_S) as scope:
        async for raw in TRANSPORTS[transport](f"{ROBOT_ADDR}:{PORT}", TOPIC):
            now = time.time()
            message = json.loads(raw)
            if message.get("op") != "publish":
                continue
            if not start:
                start = now
                scope.deadline = anyio.current_time() + duration
            if now - start < WARMUP_S:
                continue
            ages.append(now - float(message["msg"]["data"]))
            arrivals.append(now)
    used = (time.process_time() - cpu) / (time.monotonic() - wall)
    if len(ages) < 2:
        return {"transport": transport, "received": len(ages)}
    quantiles = statistics.quantiles(ages, n=100)
    return {
        "transport": transport,
        "received": len(ages),
        "window_s": round(arrivals[-1] - arrivals[0], 2),
        "delivered_hz": round((len(ages) - 1) / (arrivals[-1] - arrivals[0])),
        "age_p50_ms": round(quantiles[49] * 1000, 1),
        "age_p99_ms": round(quantiles[98] * 1000, 1),
        "browser_cpu_pct": round(100 * used),
        "longest_stall_ms": round(max(b - a for a, b in itertools.pairwise(arrivals)) * 1000, 1),
    }


async def browse_video(duration: float) -> dict[str, Any]:
    """Play ``CAMERA`` as a VP8 video track for ``duration`` s from its first frame.

    The figures are decoded frames a second and the longest time between two; a
    frame's age would need a send time in the picture, so there is none.
    """
    import httpx  # noqa: PLC0415 (the browser process only)
    from aiortc import (  # noqa: PLC0415
        RTCConfiguration,
        RTCPeerConnection,
        RTCRtpReceiver,
        RTCSessionDescription,
    )

    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    vp8 = [c for c in RTCRtpReceiver.getCapabilities("video").codecs if c.mimeType == "video/VP8"]
    pc.addTransceiver("video", direction="recvonly").setCodecPreferences(vp8)
    tracks: list[Any] = []
    got_track = anyio.Event()

    def on_track(track: Any) -> None:
        tracks.append(track)
        got_track.set()

    pc.on("track", on_track)
    arrivals: list[float] = []
    cpu, wall = time.process_time(), time.monotonic()
    try:
        await pc.setLocalDescription(await pc.createOffer())
        async with httpx.AsyncClient() as http:
            reply = await http.post(
                f"http://{ROBOT_ADDR}:{PORT}/webrtc?video={CAMERA}",
                content=pc.localDescription.sdp,
                headers={"Content-Type": "application/sdp"},
            )
        reply.raise_for_status()
        await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
        with anyio.move_on_after(CONNECT_BOUND_S) as scope:
            await got_track.wait()
            while True:
                await tracks[0].recv()
                now = time.time()
                if not arrivals:
                    scope.deadline = anyio.current_time() + duration
                arrivals.append(now)
    finally:
        await pc.close()
    used = (time.process_time() - cpu) / (time.monotonic() - wall)
    kept = [t for t in arrivals if t - arrivals[0] >= WARMUP_S] if arrivals else []
    if len(kept) < 2:
        return {"transport": "video", "received": len(kept)}
    return {
        "transport": "video",
        "received": len(kept),
        "window_s": round(kept[-1] - kept[0], 2),
        "delivered_hz": round((len(kept) - 1) / (kept[-1] - kept[0]), 1),
        "browser_cpu_pct": round(100 * used),
        "longest_stall_ms": round(max(b - a for a, b in itertools.pairwise(kept)) * 1000, 1),
    }


async def robot(rate: float) -> None:
    """The robot: a server with WebRTC on ``ROBOT_ADDR``, publishing ``TOPIC`` at ``rate`` Hz."""
    from rwt_graph.graph import Graph  # noqa: PLC0415 (the robot process only)
    from rwt_transports.server import RosbridgeServer, ServerConfig  # noqa: PLC0415
    from rwt_transports.webrtc_signal import WebRtcOptions  # noqa: PLC0415

    logging.basicConfig(stream=sys.stderr, level=logging.WARNING)
    logging.getLogger("rwt").setLevel(logging.INFO)  # event=disconnect: the session's drops
    graph = Graph()
    config = ServerConfig(host=ROBOT_ADDR, port=PORT, webrtc=WebRtcOptions())
    server = RosbridgeServer(graph, config)
    clock = graph.create_publisher(TOPIC, "std_msgs/msg/String", node="/robot")
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        tg.start_soon(_camera, graph)
        print("robot up", flush=True)
        start = time.monotonic()
        sent = 0
        while True:  # on schedule: a late tick publishes at once, no drift
            sent += 1
            await anyio.sleep(max(0.0, start + sent / rate - time.monotonic()))
            clock.publish({"data": repr(time.time())})


async def _camera(graph: Any) -> None:
    """``CAMERA`` at ``CAMERA_HZ``: the paper's synthetic 640x480 scene (4 frames looped).

    Encoded for a video track only while a peer watches it (docs/webrtc.md).
    """
    from benchmarks.paper.video import messages  # noqa: PLC0415 (the robot process only)

    frames = list(messages(4))
    publisher = graph.create_publisher(CAMERA, "sensor_msgs/msg/Image", node="/robot")
    start, index = time.monotonic(), 0
    while True:
        frame = dict(frames[index % len(frames)])
        frame["header"] = {"stamp": {"sec": index // 30, "nanosec": index % 30 * 33_333_333}}
        publisher.publish(frame)
        index += 1
        await anyio.sleep(max(0.0, start + index / CAMERA_HZ - time.monotonic()))


@contextmanager
def _namespaces(*names: str) -> Any:
    try:
        for name in names:
            subprocess.run(["ip", "netns", "add", name], check=True)
            subprocess.run(["ip", "-n", name, "link", "set", "lo", "up"], check=True)
        yield
    finally:
        for name in names:
            pids = subprocess.run(
                ["ip", "netns", "pids", name], capture_output=True, text=True, check=False
            )
            for pid in pids.stdout.split():
                with suppress(ProcessLookupError):
                    os.kill(int(pid), 9)
            subprocess.run(["ip", "netns", "del", name], check=False)


def _in(ns: str, *argv: str) -> list[str]:
    return ["ip", "netns", "exec", ns, sys.executable, "-m", "benchmarks.wan_topic", *argv]


def _cpu_s(pid: int) -> float:
    """CPU seconds (user and system) process ``pid`` used so far (/proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _dropped(log: Path, kind: str) -> int | None:
    """Messages the server dropped for the last session of ``kind`` (its ``event=disconnect``)."""
    for _ in range(300):  # the session ends once the server sees the browser leave
        found = re.findall(
            rf"event=disconnect client={kind}:\S+ .*? dropped=(\d+)", log.read_text()
        )
        if found:
            return int(found[-1])
        time.sleep(0.1)
    return None


def _browse_in(ns: str, transport: str, duration: float, log: Path) -> dict[str, Any]:
    """One transport's browser run in ``ns``: its figures and the server's drops."""
    done = subprocess.run(
        _in(ns, "browser", transport, "--duration", str(duration)),
        env=ENV,
        capture_output=True,
        text=True,
        timeout=duration + CONNECT_BOUND_S + 30,
        check=True,
    )
    row: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    if transport != "video":  # a video-only peer has no rosbridge session
        row["server_dropped"] = _dropped(log, "webrtc" if transport == "webrtc" else "ws")
    return row


def run(transports: list[str], duration: float, rate: float, profile: LinkProfile) -> list[Any]:
    """Namespaces, the link, the robot, then each transport's browser in turn: their figures."""
    robot_ns, browser_ns = f"wanrobot{os.getpid()}", f"wanbrowser{os.getpid()}"
    with _namespaces(robot_ns, browser_ns):
        link = WanLink(browser_ns, BROWSER_ADDR, robot_ns, ROBOT_ADDR, profile, seed=1)
        link.start()
        log = Path(tempfile.mkdtemp(prefix="wan_topic")) / "robot.log"
        with log.open("w") as robot_log:
            server = subprocess.Popen(
                _in(robot_ns, "robot", "--rate", str(rate)),
                env=ENV,
                stdout=subprocess.PIPE,
                stderr=robot_log,
                text=True,
            )
        try:
            assert server.stdout is not None
            assert server.stdout.readline().strip() == "robot up"
            rows = []
            for transport in transports:
                cpu, wall = _cpu_s(server.pid), time.monotonic()
                row = _browse_in(browser_ns, transport, duration, log)
                used = (_cpu_s(server.pid) - cpu) / (time.monotonic() - wall)
                row["robot_cpu_pct"] = round(100 * used)  # of one core, the browser's run
                rows.append(row)
        finally:
            server.terminate()
            server.wait(10)
            if server.stdout is not None:
                server.stdout.close()
            link.stop()
    print(f"link robot->browser {link.b_to_a.stats}, browser->robot {link.a_to_b.stats}")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("role", nargs="?", default="run", choices=["run", "robot", "browser"])
    parser.add_argument("transport_name", nargs="?", default=None)
    parser.add_argument("--transport", action="append", choices=[*sorted(TRANSPORTS), "video"])
    parser.add_argument("--duration", type=float, default=15.0)
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--delay-ms", type=float, default=30.0)
    parser.add_argument("--jitter-ms", type=float, default=10.0)
    parser.add_argument("--loss", type=float, default=0.02)
    parser.add_argument("--rate-mbit", type=float, default=15.0)
    args = parser.parse_args()
    if args.role == "robot":
        anyio.run(robot, args.rate)
        return
    if args.role == "browser":
        if args.transport_name == "video":
            row = anyio.run(browse_video, args.duration)
        else:
            row = anyio.run(browse, args.transport_name, args.duration)
        print(json.dumps(row), flush=True)
        return
    profile = LinkProfile(
        args.delay_ms / 1000, args.jitter_ms / 1000, args.loss, args.rate_mbit * 1e6
    )
    chosen = args.transport or ["websocket", "webrtc", "video"]
    rows = run(chosen, args.duration, args.rate, profile)
    link = (
        f"{args.delay_ms:g} ms +- {args.jitter_ms:g} ms, {args.loss:.0%} loss,"
        f" {args.rate_mbit:g} Mbit/s"
    )
    print(f"WAN link each way: {link}; {args.rate:g} Hz std_msgs/String")
    print(
        "| transport | delivered msg/s | server drops | age p50 | age p99 | longest stall"
        " | robot CPU | browser CPU |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['transport']} | {row.get('delivered_hz')} | "
            f"{row.get('server_dropped')} | "
            f"{row.get('age_p50_ms', '-')} ms | {row.get('age_p99_ms', '-')} ms | "
            f"{row.get('longest_stall_ms')} ms | {row.get('robot_cpu_pct')} % | "
            f"{row.get('browser_cpu_pct')} % |"
        )
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps({"link": link, "rate_hz": args.rate, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
