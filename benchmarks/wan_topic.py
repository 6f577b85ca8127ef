"""A 1 kHz topic and a 30 Hz camera to a browser behind a WAN link, over each transport.

The robot (an in-process ``RosbridgeServer`` with ``--webrtc`` and the video server,
publishing ``std_msgs/String`` at ``--rate`` Hz whose data is its send time, and a 30 Hz
640x480 camera, ``CAMERA``) and the browser (one subscriber per transport, run one after
the other) are in two network namespaces joined by benchmarks/wanlink.py (30 ms +- 10 ms
each way, 2 % loss, 15 Mbit/s by default).

The topic's transports (``TRANSPORTS``): ``websocket`` (TCP), ``webrtc`` (the
``rosbridge`` data channel, reliable and ordered: SCTP over DTLS over UDP) and
``webrtc-lossy`` (subscribed on the ``rosbridge-lossy`` channel: unordered, never
retransmitted, the newest message of the topic; docs/webrtc.md), and where libdatachannel-py
imports (Python 3.12+, D51) ``webrtc-native`` and ``webrtc-native-lossy``, the same on the
native stack at both ends (the robot's second server, ``NATIVE_PORT``, and a libdatachannel
peer). Per transport: messages
delivered a second, messages the server dropped for the session (its slow-consumer rule,
D24), the age of each message when it arrived (receive time - send time, the same clock:
one machine) at p50 and p99, and the longest stall (the longest time between two
messages, where 1 ms is expected).

The camera's transports (``PICTURES``): ``vp8`` and ``h264`` (video tracks,
docs/webrtc.md; ``vp8-native`` and ``h264-native`` from the native stack's server),
``mjpeg`` (the video server's ``/stream``, as an ``<img>`` shows it) and ``cbor-image``
(a rosbridge subscription with ``compression: cbor`` over the WebSocket, as a roslib page
makes it). Each picture carries its publish time painted in as blocks
(``stamp_picture``), read back from the decoded picture (``read_stamp``): pictures a
second, their age at p50 and p99, the longest stall, and pictures whose stamp did not read.

Run (root, network namespaces; a few seconds a transport)::

    nice -n 10 python -m benchmarks.wan_topic --duration 12 [--transport webrtc ...] [--trace-sctp]

Results: a table on stdout and ``benchmarks/results/wan_topic.json``; ``--trace-sctp``
puts aiortc's SCTP state in the robot's log each second (benchmarks/sctp_trace.py).
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
import zlib
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import contextmanager, suppress
from functools import partial
from pathlib import Path
from typing import Any

import anyio

from benchmarks.wanlink import LinkProfile, WanLink

ROBOT_ADDR = "198.18.5.1"
BROWSER_ADDR = "198.18.5.2"
PORT = 9090
NATIVE_PORT = 9091
"""The robot's second server, the same graph on the native WebRTC stack (D51), where
libdatachannel-py imports."""
TOPIC = "/wan_clock"
WARMUP_S = 2.0
"""Seconds of each run left out of the figures (connecting, the first window)."""

CAMERA = "/wan_camera"
CAMERA_HZ = 30.0
VIDEO_PORT = 8080
"""The robot's video server (MJPEG over HTTP, ``rwt serve --video``)."""
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


async def _answer(base: str, offer: str) -> str:
    """POST ``offer`` to the robot's ``/webrtc``: the answer's SDP."""
    import httpx  # noqa: PLC0415 (the browser process only)

    async with httpx.AsyncClient() as http:
        reply = await http.post(
            f"http://{base}/webrtc", content=offer, headers={"Content-Type": "application/sdp"}
        )
    reply.raise_for_status()
    return reply.text


async def _subscribed(
    channels: list[Any], topic: str, connect: Callable[[], Awaitable[None]]
) -> AsyncIterator[str | bytes]:
    """Once ``connect`` made the peer connection and ``channels`` (aiortc's or the native
    ones: ``on``, ``send``) opened, subscribe to ``topic`` on the last one: its messages."""
    inbox: list[str | bytes] = []
    arrived = anyio.Event()
    opened = [anyio.Event() for _ in channels]

    def on_message(message: str | bytes) -> None:
        inbox.append(message)
        arrived.set()

    for channel, event in zip(channels, opened, strict=True):
        channel.on("open", event.set)
    channels[-1].on("message", on_message)
    await connect()
    with anyio.fail_after(20):
        for event in opened:
            await event.wait()
    channels[-1].send(json.dumps({"op": "subscribe", "topic": topic, "type": "std_msgs/String"}))
    while True:
        await arrived.wait()
        arrived = anyio.Event()
        batch, inbox[:] = inbox[:], []
        for message in batch:
            yield message


async def _data_channel(base: str, topic: str, *, lossy: bool) -> AsyncIterator[str | bytes]:
    """The topic over ``rosbridge``, or subscribed on ``rosbridge-lossy`` (docs/webrtc.md)."""
    from aiortc import (  # noqa: PLC0415
        RTCConfiguration,
        RTCPeerConnection,
        RTCSessionDescription,
    )

    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    channels = [pc.createDataChannel("rosbridge")]
    if lossy:  # the settings the server keeps the channel for (D36)
        channels.append(pc.createDataChannel("rosbridge-lossy", ordered=False, maxRetransmits=0))

    async def connect() -> None:
        await pc.setLocalDescription(await pc.createOffer())
        answer = await _answer(base, pc.localDescription.sdp)
        await pc.setRemoteDescription(RTCSessionDescription(answer, "answer"))

    try:
        async for message in _subscribed(channels, topic, connect):
            yield message
    finally:
        await pc.close()


async def _native_channel(base: str, topic: str, *, lossy: bool) -> AsyncIterator[str | bytes]:
    """``_data_channel`` with libdatachannel on both ends: a libdatachannel peer (each
    channel behind the server's ``NativeDataChannel``) to the robot's native server."""
    import asyncio  # noqa: PLC0415 (the browser process only)

    import libdatachannel as ldc  # noqa: PLC0415 (optional: Python 3.12+)

    from benchmarks.webrtc import gathered  # noqa: PLC0415
    from rwt_transports.webrtc.native import Inflow, NativeDataChannel  # noqa: PLC0415

    base = base.replace(f":{PORT}", f":{NATIVE_PORT}")
    loop = asyncio.get_running_loop()
    pc = ldc.PeerConnection(ldc.Configuration())
    inits = [None]
    if lossy:  # the settings the server keeps the channel for (D36)
        init, reliability = ldc.DataChannelInit(), ldc.Reliability()
        reliability.unordered, reliability.max_retransmits = True, 0
        init.reliability = reliability
        inits.append(init)
    labels = ["rosbridge", "rosbridge-lossy"]
    channels = [
        NativeDataChannel(pc.create_data_channel(label, init), loop, Inflow(1 << 40, int), 1 << 30)
        for label, init in zip(labels, inits, strict=False)
    ]
    for channel in channels:
        channel.listen()

    async def connect() -> None:
        await gathered(ldc, pc)
        answer = await _answer(base, str(pc.local_description()))
        pc.set_remote_description(ldc.Description(answer, ldc.Description.Type.Answer))

    try:
        async for message in _subscribed(channels, topic, connect):
            yield message
    finally:  # the run ends by cancelling: closed anyway (a peer connection left open aborts)
        with anyio.CancelScope(shield=True):
            await anyio.to_thread.run_sync(pc.close)


TRANSPORTS: dict[str, Transport] = {
    "websocket": _websocket,
    "webrtc": partial(_data_channel, lossy=False),
    "webrtc-lossy": partial(_data_channel, lossy=True),
    "webrtc-native": partial(_native_channel, lossy=False),
    "webrtc-native-lossy": partial(_native_channel, lossy=True),
}
"""The browser's transports of the 1 kHz topic by name."""


async def browse(transport: str, duration: float, warmup_s: float = WARMUP_S) -> dict[str, Any]:
    """Subscribe over ``transport`` for ``duration`` s from its first message; the figures
    after the first ``warmup_s`` s (a slow connection on a busy machine shortens no run)."""
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
            if now - start < warmup_s:
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


# ---- the camera's pictures, each stamped with its publish time ---------------------

STAMP_BLOCK = 32
"""Side of one block of the stamp, px: two macroblocks of VP8 and H.264 (16 px) wide, so
each block is flat inside its own blocks and survives compression."""
STAMP_BITS = 32
"""The publish time in ms modulo 2**32 (49 days), then an 8-bit check of it."""
_BLOCKS_PER_ROW = 20  # 640 px / 32 px: the stamp is the top 64 rows of the picture


def stamp_picture(pixels: Any, now: float) -> None:
    """Paint ``now`` (s, ``time.time()``) into ``pixels`` (rgb8, at least 640 wide) in place.

    Blocks of ``STAMP_BLOCK`` px, black for 0 and white for 1: the low ``STAMP_BITS`` of
    the time in ms, most significant first, then ``zlib.crc32`` of it (8 bits), two rows.
    """
    value = int(now * 1000) % (1 << STAMP_BITS)
    for index, bit in enumerate(_stamp_bits(value)):
        row, column = divmod(index, _BLOCKS_PER_ROW)
        y, x = row * STAMP_BLOCK, column * STAMP_BLOCK
        pixels[y : y + STAMP_BLOCK, x : x + STAMP_BLOCK] = 255 if bit else 0


def read_stamp(gray: Any, now: float) -> float | None:
    """The publish time painted by ``stamp_picture`` into a decoded picture, s; None when
    its check fails (a picture too damaged to read). ``gray``: (height, width) luminance.
    ``now`` (s) gives the high bits the stamp leaves out.
    """
    half, quarter = STAMP_BLOCK // 2, STAMP_BLOCK // 4
    bits = []
    for index in range(STAMP_BITS + 8):
        row, column = divmod(index, _BLOCKS_PER_ROW)
        y, x = row * STAMP_BLOCK + half, column * STAMP_BLOCK + half
        centre = gray[y - quarter : y + quarter, x - quarter : x + quarter]
        bits.append(int(centre.mean() > 128))
    value = int("".join(map(str, bits[:STAMP_BITS])), 2)
    if bits != _stamp_bits(value):
        return None
    now_ms = int(now * 1000)
    age_ms = (now_ms - value) % (1 << STAMP_BITS)
    return (now_ms - age_ms) / 1000


def _stamp_bits(value: int) -> list[int]:
    check = zlib.crc32(value.to_bytes(4, "big")) & 0xFF
    word = (value << 8) | check
    return [(word >> shift) & 1 for shift in range(STAMP_BITS + 7, -1, -1)]


Pictures = AsyncIterator[Any]
"""A picture transport's decoded pictures, each as (height, width) luminance."""


async def _video_track(codec: str, port: int = PORT) -> Pictures:
    """``CAMERA`` played as a video track in ``codec`` (``VP8``, ``H264``) from ``port``'s
    server (``NATIVE_PORT``: libdatachannel sends it, D51)."""
    import httpx  # noqa: PLC0415 (the browser process only)
    from aiortc import (  # noqa: PLC0415
        RTCConfiguration,
        RTCPeerConnection,
        RTCRtpReceiver,
        RTCSessionDescription,
    )

    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    codecs = RTCRtpReceiver.getCapabilities("video").codecs
    chosen = [c for c in codecs if c.mimeType == f"video/{codec}"]
    pc.addTransceiver("video", direction="recvonly").setCodecPreferences(chosen)
    tracks: list[Any] = []
    got_track = anyio.Event()

    def on_track(track: Any) -> None:
        tracks.append(track)
        got_track.set()

    pc.on("track", on_track)
    base, location = f"http://{ROBOT_ADDR}:{port}", None
    try:
        await pc.setLocalDescription(await pc.createOffer())
        async with httpx.AsyncClient() as http:
            reply = await http.post(
                f"{base}/webrtc?video={CAMERA}",
                content=pc.localDescription.sdp,
                headers={"Content-Type": "application/sdp"},
            )
        reply.raise_for_status()
        location = reply.headers.get("Location")
        await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
        await got_track.wait()
        while True:
            frame = await tracks[0].recv()
            yield frame.to_ndarray(format="gray")
    finally:
        # as a WHEP player stops: DELETE, so the robot's stream stops now, not when the
        # peer connection's close (lost on the lossy link, maybe) or consent ends it
        with anyio.move_on_after(5, shield=True), suppress(httpx.HTTPError):
            if location:
                async with httpx.AsyncClient() as http:
                    await http.delete(base + location)
        await pc.close()


async def _vp8() -> Pictures:
    async for picture in _video_track("VP8"):
        yield picture


async def _h264() -> Pictures:
    async for picture in _video_track("H264"):
        yield picture


async def _vp8_native() -> Pictures:
    async for picture in _video_track("VP8", NATIVE_PORT):
        yield picture


async def _h264_native() -> Pictures:
    async for picture in _video_track("H264", NATIVE_PORT):
        yield picture


async def _mjpeg() -> Pictures:
    """``CAMERA`` from the video server's ``/stream`` (MJPEG, its default quality), as an
    ``<img>`` would: each part's JPEG decoded."""
    import io  # noqa: PLC0415

    import httpx  # noqa: PLC0415 (the browser process only)
    import numpy as np  # noqa: PLC0415
    from PIL import Image  # noqa: PLC0415

    url = f"http://{ROBOT_ADDR}:{VIDEO_PORT}/stream?topic={CAMERA}&type=mjpeg"
    buffer = b""
    async with httpx.AsyncClient(timeout=None) as http, http.stream("GET", url) as reply:
        reply.raise_for_status()
        async for chunk in reply.aiter_raw():
            buffer += chunk
            while True:  # every whole part in the buffer: headers, then Content-Length bytes
                head_end = buffer.find(b"\r\n\r\n")
                found = re.search(rb"Content-Length: (\d+)", buffer[: max(head_end, 0)])
                if head_end < 0 or found is None or len(buffer) < head_end + 4 + int(found[1]):
                    break
                body_start = head_end + 4
                jpeg = buffer[body_start : body_start + int(found[1])]
                buffer = buffer[body_start + len(jpeg) :]
                yield np.asarray(Image.open(io.BytesIO(jpeg)).convert("L"))


async def _cbor_image() -> Pictures:
    """``CAMERA`` subscribed over the WebSocket with ``compression: cbor``, as a roslib
    page would (no throttle, no queue length): each message's pixels."""
    import cbor2  # noqa: PLC0415 (the browser process only)
    import numpy as np  # noqa: PLC0415
    import websockets  # noqa: PLC0415

    subscribe = {
        "op": "subscribe",
        "topic": CAMERA,
        "type": "sensor_msgs/Image",
        "compression": "cbor",
    }
    async with websockets.connect(f"ws://{ROBOT_ADDR}:{PORT}", max_size=None) as ws:
        await ws.send(json.dumps(subscribe))
        async for raw in ws:
            if not isinstance(raw, bytes):
                continue  # a status
            message = cbor2.loads(raw)
            if message.get("op") != "publish":
                continue
            image = message["msg"]
            pixels = np.frombuffer(bytes(image["data"]), np.uint8)
            pixels = pixels.reshape(image["height"], image["width"], 3)
            yield pixels.mean(axis=2)


PICTURES: dict[str, Callable[[], Pictures]] = {
    "vp8": _vp8,
    "h264": _h264,
    "vp8-native": _vp8_native,
    "h264-native": _h264_native,
    "mjpeg": _mjpeg,
    "cbor-image": _cbor_image,
}
"""The browser's transports of the camera by name: each yields decoded pictures."""


async def browse_pictures(
    transport: str, duration: float, warmup_s: float = WARMUP_S
) -> dict[str, Any]:
    """Watch ``CAMERA`` over ``transport`` for ``duration`` s from its first picture.

    The figures (after the first ``warmup_s`` s): pictures a second, their age (the stamp painted
    into each at publish, read back from the decoded picture) and the longest time
    between two; pictures whose stamp does not read are counted, not aged.
    """
    ages: list[float] = []
    arrivals: list[float] = []
    unread = 0
    start = 0.0
    cpu, wall = time.process_time(), time.monotonic()
    with anyio.move_on_after(CONNECT_BOUND_S) as scope:
        async for gray in PICTURES[transport]():
            now = time.time()
            if not start:
                start = now
                scope.deadline = anyio.current_time() + duration
            if now - start < warmup_s:
                continue
            arrivals.append(now)
            sent = read_stamp(gray, now)
            if sent is None:
                unread += 1
            else:
                ages.append(now - sent)
    used = (time.process_time() - cpu) / (time.monotonic() - wall)
    row: dict[str, Any] = {"transport": transport, "received": len(arrivals), "unread": unread}
    if len(arrivals) >= 2:
        window = arrivals[-1] - arrivals[0]
        stall = max(b - a for a, b in itertools.pairwise(arrivals))
        row.update(
            window_s=round(window, 2),
            delivered_hz=round((len(arrivals) - 1) / window, 1),
            longest_stall_ms=round(stall * 1000, 1),
        )
    if ages:
        ages.sort()
        row.update(
            age_p50_ms=round(ages[len(ages) // 2] * 1000, 1),
            age_p99_ms=round(ages[min(len(ages) - 1, int(len(ages) * 0.99))] * 1000, 1),
        )
    row["browser_cpu_pct"] = round(100 * used)
    return row


async def robot(rate: float, trace_sctp: bool = False) -> None:
    """The robot: a server with WebRTC on ``ROBOT_ADDR``, publishing ``TOPIC`` at ``rate`` Hz,
    the camera, and the video server on ``VIDEO_PORT``. ``trace_sctp``: aiortc's SCTP
    sender's state in its log (benchmarks/sctp_trace.py)."""
    from rwt_graph.graph import Graph  # noqa: PLC0415 (the robot process only)
    from rwt_transports.server import RosbridgeServer, ServerConfig  # noqa: PLC0415
    from rwt_transports.webrtc.signalling import WebRtcOptions  # noqa: PLC0415
    from rwt_video import VideoConfig, serve_video  # noqa: PLC0415

    logging.basicConfig(stream=sys.stderr, level=logging.WARNING)
    logging.getLogger("rwt").setLevel(logging.INFO)  # event=disconnect: the session's drops
    graph = Graph()
    from rwt_transports.webrtc.native import native_missing  # noqa: PLC0415

    config = ServerConfig(host=ROBOT_ADDR, port=PORT, webrtc=WebRtcOptions(stack="aiortc"))
    server = RosbridgeServer(graph, config)
    native = None
    if native_missing() is None:  # the same graph on the native stack (D51)
        options = WebRtcOptions(stack="native")
        native_config = ServerConfig(host=ROBOT_ADDR, port=NATIVE_PORT, webrtc=options)
        native = RosbridgeServer(graph, native_config)
    clock = graph.create_publisher(TOPIC, "std_msgs/msg/String", node="/robot")
    async with anyio.create_task_group() as tg:
        if trace_sctp:
            from benchmarks import sctp_trace  # noqa: PLC0415 (only when tracing)

            sctp_trace.install()
            tg.start_soon(sctp_trace.report)
        await tg.start(server.serve)
        if native is not None:
            await tg.start(native.serve)
        await tg.start(serve_video, graph, VideoConfig(host=ROBOT_ADDR, port=VIDEO_PORT))
        tg.start_soon(_camera, graph)
        print("robot up", flush=True)
        start = time.monotonic()
        sent = 0
        while True:  # on schedule: a late tick publishes at once, no drift
            sent += 1
            await anyio.sleep(max(0.0, start + sent / rate - time.monotonic()))
            clock.publish({"data": repr(time.time())})


async def _camera(graph: Any) -> None:
    """``CAMERA`` at ``CAMERA_HZ``: the paper's synthetic 640x480 scene (4 frames looped),
    each stamped with its publish time in the picture (``stamp_picture``) and the header.

    Encoded for a video track or MJPEG only while a peer watches it (docs/webrtc.md).
    """
    from benchmarks.paper.video import camera_frames  # noqa: PLC0415 (the robot process only)
    from rwt_graph.media import array_to_image  # noqa: PLC0415

    frames = list(camera_frames(4))
    publisher = graph.create_publisher(CAMERA, "sensor_msgs/msg/Image", node="/robot")
    start, index = time.monotonic(), 0
    while True:
        pixels = frames[index % len(frames)].copy()
        now = time.time()
        stamp_picture(pixels, now)
        header = {"stamp": {"sec": int(now), "nanosec": int(now % 1 * 1e9)}}
        publisher.publish(array_to_image(pixels, "rgb8", header=header))
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


def _disconnects(log: Path, kind: str) -> list[int]:
    """The drops of each session of ``kind`` that ended so far (its ``event=disconnect``)."""
    pattern = rf"event=disconnect client={kind}:\S+ .*? dropped=(\d+)"
    return [int(found) for found in re.findall(pattern, log.read_text())]


def _dropped(log: Path, kind: str, before: int) -> int | None:
    """Messages the server dropped for the session of ``kind`` that ends after ``before``
    others of its kind ended (a session with a long outbox ends a while after its peer)."""
    for _ in range(300):
        ended = _disconnects(log, kind)
        if len(ended) > before:
            return ended[before]
        time.sleep(0.1)
    return None


def _browse_in(
    ns: str, transport: str, duration: float, warmup_s: float, log: Path
) -> dict[str, Any]:
    """One transport's browser run in ``ns``: its figures and the server's drops."""
    kind = "webrtc" if "webrtc" in transport else "ws"
    before = len(_disconnects(log, kind))
    done = subprocess.run(
        _in(ns, "browser", transport, "--duration", str(duration), "--warmup", str(warmup_s)),
        env=ENV,
        capture_output=True,
        text=True,
        timeout=duration + CONNECT_BOUND_S + 30,
        check=True,
    )
    row: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    if transport in TRANSPORTS or transport == "cbor-image":  # a rosbridge session's drops
        row["server_dropped"] = _dropped(log, kind, before)
    return row


def run(
    transports: list[str],
    duration: float,
    rate: float,
    profile: LinkProfile,
    trace_sctp: bool = False,
    warmup_s: float = WARMUP_S,
) -> list[Any]:
    """Namespaces, the link, the robot, then each transport's browser in turn: their figures
    (``duration`` s each from its first message, the first ``warmup_s`` s left out).

    The robot's log (its path printed first) holds its sessions and, with ``trace_sctp``,
    aiortc's SCTP state each second.
    """
    robot_ns, browser_ns = f"wanrobot{os.getpid()}", f"wanbrowser{os.getpid()}"
    with _namespaces(robot_ns, browser_ns):
        link = WanLink(browser_ns, BROWSER_ADDR, robot_ns, ROBOT_ADDR, profile, seed=1)
        link.start()
        log = Path(tempfile.mkdtemp(prefix="wan_topic")) / "robot.log"
        print(f"robot log: {log}", flush=True)
        with log.open("w") as robot_log:
            server = subprocess.Popen(
                _in(robot_ns, "robot", "--rate", str(rate), *["--trace-sctp"] * trace_sctp),
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
                row = _browse_in(browser_ns, transport, duration, warmup_s, log)
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
    parser.add_argument("--transport", action="append", choices=[*TRANSPORTS, *PICTURES])
    parser.add_argument("--duration", type=float, default=15.0)
    parser.add_argument(
        "--warmup", type=float, default=WARMUP_S, help="seconds of each run left out first"
    )
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--delay-ms", type=float, default=30.0)
    parser.add_argument("--jitter-ms", type=float, default=10.0)
    parser.add_argument("--loss", type=float, default=0.02)
    parser.add_argument("--rate-mbit", type=float, default=15.0)
    parser.add_argument(
        "--trace-sctp", action="store_true", help="aiortc's SCTP state in the robot's log"
    )
    args = parser.parse_args()
    if args.role == "robot":
        anyio.run(robot, args.rate, args.trace_sctp)
        return
    if args.role == "browser":
        if args.transport_name in PICTURES:
            row = anyio.run(browse_pictures, args.transport_name, args.duration, args.warmup)
        else:
            row = anyio.run(browse, args.transport_name, args.duration, args.warmup)
        print(json.dumps(row), flush=True)
        return
    profile = LinkProfile(
        args.delay_ms / 1000, args.jitter_ms / 1000, args.loss, args.rate_mbit * 1e6
    )
    chosen = args.transport or [*TRANSPORTS, *PICTURES]
    from rwt_transports.webrtc.native import native_missing  # noqa: PLC0415

    if (missing := native_missing()) is not None and any("native" in t for t in chosen):
        print(f"without the native stack's rows: {missing}", file=sys.stderr)
        chosen = [t for t in chosen if "native" not in t]
    rows = run(chosen, args.duration, args.rate, profile, args.trace_sctp, args.warmup)
    link = (
        f"{args.delay_ms:g} ms +- {args.jitter_ms:g} ms, {args.loss:.0%} loss,"
        f" {args.rate_mbit:g} Mbit/s"
    )
    print(f"WAN link each way: {link}; {args.rate:g} Hz std_msgs/String")
    print(
        "| transport | delivered a second | server drops | age p50 | age p99 | longest stall"
        " | robot CPU | browser CPU | stamps unread |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['transport']} | {row.get('delivered_hz')} | "
            f"{row.get('server_dropped')} | "
            f"{row.get('age_p50_ms', '-')} ms | {row.get('age_p99_ms', '-')} ms | "
            f"{row.get('longest_stall_ms')} ms | {row.get('robot_cpu_pct')} % | "
            f"{row.get('browser_cpu_pct')} % | {row.get('unread', '')} |"
        )
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps({"link": link, "rate_hz": args.rate, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
