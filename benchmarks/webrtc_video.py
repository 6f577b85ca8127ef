"""WebRTC video tracks of a 640x480 30 Hz camera: bandwidth beside Table I, CPU per viewer.

Two parts, both on the paper's synthetic camera (``benchmarks.paper.video``: a
textured scene panning past, a moving object, sensor noise):

- **Bandwidth** (offline, deterministic): ``--frames`` frames encoded by the
  video tracks' shared encoder (``rwt_video.rtp.RtpEncoder``), cut into RTP packets
  by aiortc's packetizers, each packet counted as it goes on the wire (RTP header
  with aiortc's header extensions, the SRTP tag; no UDP/IP, as the HTTP rows count
  no TCP/IP), at 30 frames a second. Beside them, on the same frames, Table I's
  MJPEG quality 90 and VP8-over-HTTP rows (``benchmarks.paper._streams``). VP8 and
  H.264 at 100 kbit/s (the paper's setting) and at 1 Mbit/s (the tracks' default).
  Also each encoder's CPU a frame, and aiortc's own encoders' (one per peer
  without sharing) on the same frames.
- **CPU per stream and per extra viewer** (live): a server process (an embedded rwt
  with ``--webrtc`` and the camera at 30 Hz) watched by 0, 1 and ``--viewers``
  aiortc WHEP players (this process, which decodes), ``--seconds`` each; the
  server's CPU (% of a core) in each case gives the cost of the stream (1 viewer
  minus none) and of each extra viewer ((N minus 1) / (N - 1)).

Run: ``python -m benchmarks.webrtc_video [--frames 900] [--seconds 10] [--viewers 4]``
(``--quick``: 30 frames, 3 s a case). Results: ``results/webrtc_video.json``.
"""

from __future__ import annotations

import argparse
import asyncio
import fractions
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "webrtc_video.json"
CAMERA = "/bench/camera"
RATE_HZ = 30.0
KB = 1000.0
SRTP_TAG_BYTES = 10  # AES_CM_128_HMAC_SHA1_80, what aiortc negotiates
SETTLE_S = 3.0
"""Seconds the viewers play before the CPU is measured: every track has started."""


# ---- bandwidth (offline) ------------------------------------------------------------


@dataclass
class Encoded:
    """One codec's run over the frames: wire bytes and encode CPU."""

    name: str
    frames: int
    wire_bytes: int
    cpu_s: float
    packets: int = 0

    @property
    def kb_per_s(self) -> float:
        return self.wire_bytes / max(self.frames, 1) * RATE_HZ / KB

    @property
    def cpu_ms(self) -> float:
        return self.cpu_s / max(self.frames, 1) * 1000


def _rtp_sizes(codec: str) -> tuple[object, object]:
    """aiortc's packetizer for ``codec`` and a function: payload -> bytes on the wire."""
    from aiortc.codecs import get_encoder  # noqa: PLC0415
    from aiortc.rtcrtpparameters import (  # noqa: PLC0415
        RTCRtpCodecParameters,
        RTCRtpHeaderExtensionParameters,
        RTCRtpParameters,
    )
    from aiortc.rtp import HeaderExtensionsMap, RtpPacket  # noqa: PLC0415

    parameters = RTCRtpCodecParameters(mimeType=codec, clockRate=90000, payloadType=96)
    extensions = HeaderExtensionsMap()
    extensions.configure(
        RTCRtpParameters(
            headerExtensions=[  # aiortc's video extensions, as it answers a browser
                RTCRtpHeaderExtensionParameters(id=1, uri="urn:ietf:params:rtp-hdrext:sdes:mid"),
                RTCRtpHeaderExtensionParameters(
                    id=2, uri="http://www.webrtc.org/experiments/rtp-hdrext/abs-send-time"
                ),
            ]
        )
    )

    def wire(payload: bytes) -> int:
        packet = RtpPacket(payload_type=96, sequence_number=1, timestamp=1)
        packet.ssrc = 1
        packet.payload = payload
        packet.extensions.abs_send_time = 123456
        packet.extensions.mid = "0"
        return len(packet.serialize(extensions)) + SRTP_TAG_BYTES

    return get_encoder(parameters), wire


def rtp_track(messages: Iterable[dict[str, object]], codec: str, bitrate: int) -> Encoded:
    """The shared encoder of a video track, packetized as aiortc sends it."""
    import av  # noqa: PLC0415

    from rwt_video.params import StreamParams, StreamType  # noqa: PLC0415
    from rwt_video.rtp import RtpEncoder  # noqa: PLC0415

    kind = StreamType.VP8 if codec == "video/VP8" else StreamType.H264
    encoder = RtpEncoder(StreamParams(CAMERA, kind, bitrate=bitrate))
    packer, wire = _rtp_sizes(codec)
    result = Encoded(f"{kind.value} {bitrate // 1000} kbit/s (WebRTC track)", 0, 0, 0.0)
    for msg in messages:
        started = time.process_time()
        frames = encoder.encode(msg)
        result.cpu_s += time.process_time() - started
        result.frames += 1
        for frame in frames:
            packet = av.Packet(frame.data)
            packet.pts, packet.time_base = frame.pts_ms, fractions.Fraction(1, 1000)
            payloads, _ = packer.pack(packet)  # type: ignore[attr-defined]
            result.packets += len(payloads)
            result.wire_bytes += sum(wire(p) for p in payloads)  # type: ignore[operator]
    return result


def aiortc_encoder(messages: Iterable[dict[str, object]], codec: str) -> Encoded:
    """aiortc's own encoder (one per peer without sharing), its default rate, same frames."""
    import av  # noqa: PLC0415
    from aiortc.codecs import get_encoder  # noqa: PLC0415
    from aiortc.rtcrtpparameters import RTCRtpCodecParameters  # noqa: PLC0415

    from rwt_graph.media import image_to_display  # noqa: PLC0415

    parameters = RTCRtpCodecParameters(mimeType=codec, clockRate=90000, payloadType=96)
    encoder = get_encoder(parameters)
    result = Encoded(f"aiortc's own {codec} encoder", 0, 0, 0.0)
    for index, msg in enumerate(messages):
        frame = av.VideoFrame.from_ndarray(image_to_display(msg), format="rgb24")
        frame.pts, frame.time_base = index * 3000, fractions.Fraction(1, 90000)
        started = time.process_time()
        payloads, _ = encoder.encode(frame)
        result.cpu_s += time.process_time() - started
        result.frames += 1
        result.wire_bytes += sum(len(p) for p in payloads)
    return result


def bandwidth_rows(frames: int) -> list[dict[str, object]]:
    """Table I's MJPEG and VP8-over-HTTP rows beside the WebRTC tracks, one run."""
    from benchmarks.paper._streams import mjpeg, video  # noqa: PLC0415
    from benchmarks.paper.video import PAPER, messages  # noqa: PLC0415
    from rwt_video.params import StreamParams, StreamType  # noqa: PLC0415

    cached = list(messages(frames))
    jpeg = mjpeg(cached, StreamParams(CAMERA, StreamType.MJPEG, quality=90))
    http_vp8 = video(cached, StreamParams(CAMERA, StreamType.VP8, bitrate=100_000))
    rows = [
        _row("MJPEG quality 90 (HTTP)", jpeg.kb_per_s, jpeg.cpu_ms_per_frame, PAPER["mjpeg"]),
        _row("VP8 100 kbit/s (HTTP, WebM)", http_vp8.kb_per_s, http_vp8.cpu_ms_per_frame, 342.2),
    ]
    for codec in ("video/VP8", "video/H264"):
        for bitrate in (100_000, 1_000_000):
            track = rtp_track(cached, codec, bitrate)
            rows.append(_row(track.name, track.kb_per_s, track.cpu_ms, None, track.packets))
    for codec in ("video/VP8", "video/H264"):
        own = aiortc_encoder(cached, codec)
        rows.append(_row(own.name, own.kb_per_s, own.cpu_ms, None))
    base = rows[0]["kb_per_s"]
    for row in rows:
        row["vs_mjpeg"] = round(float(row["kb_per_s"]) / float(base), 3)  # type: ignore[arg-type]
    return rows


def _row(
    name: str, kb_per_s: float, cpu_ms: float, paper: float | None, packets: int | None = None
) -> dict[str, object]:
    return {
        "stream": name,
        "kb_per_s": round(kb_per_s, 1),
        "encode_cpu_ms_per_frame": round(cpu_ms, 2),
        "paper_kb_per_s": paper,
        "rtp_packets": packets,
    }


# ---- CPU per viewer (live) ----------------------------------------------------------


async def _robot() -> None:
    """The server process: rwt with WebRTC and the camera at 30 Hz (4 frames looped)."""
    import anyio  # noqa: PLC0415

    from benchmarks.paper.video import messages  # noqa: PLC0415
    from rwt import Graph, RosbridgeServer, ServerConfig  # noqa: PLC0415
    from rwt_transports.webrtc.signalling import WebRtcOptions  # noqa: PLC0415

    frames = list(messages(4))
    graph = Graph()
    server = RosbridgeServer(graph, ServerConfig(host="127.0.0.1", port=0, webrtc=WebRtcOptions()))
    publisher = graph.create_publisher(CAMERA, "sensor_msgs/msg/Image")

    async def camera() -> None:
        due, index = time.monotonic(), 0
        while True:
            frame = dict(frames[index % len(frames)])
            frame["header"] = {"stamp": {"sec": index // 30, "nanosec": index % 30 * 33_333_333}}
            publisher.publish(frame)
            index += 1
            due = max(due + 1 / RATE_HZ, time.monotonic())  # a late frame is not made up
            await anyio.sleep(max(0.0, due - time.monotonic()))

    async with anyio.create_task_group() as tg:
        tg.start_soon(camera)
        url = await tg.start(server.serve)
        print(f"listening on {url}", flush=True)
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for _ in signals:
                tg.cancel_scope.cancel()
                return


async def _watch(base: str, count: int, codec: str, seconds: float, pid: int) -> dict[str, float]:
    """``count`` aiortc players for ``seconds`` after ``SETTLE_S``: server CPU, frames got."""
    import httpx  # noqa: PLC0415
    from aiortc import (  # noqa: PLC0415
        RTCConfiguration,
        RTCPeerConnection,
        RTCRtpReceiver,
        RTCSessionDescription,
    )

    from .servers import proc_stats  # noqa: PLC0415

    pcs, got = [], [0] * count

    async def play(index: int, track: object) -> None:
        while True:
            try:
                await track.recv()  # type: ignore[attr-defined]
            except Exception:  # the track ended
                return
            got[index] += 1

    tasks = []
    async with httpx.AsyncClient(base_url=base) as http:
        for index in range(count):
            pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
            capabilities = RTCRtpReceiver.getCapabilities("video")
            chosen = [c for c in capabilities.codecs if c.mimeType == codec]
            pc.addTransceiver("video", direction="recvonly").setCodecPreferences(chosen)
            pc.on("track", lambda t, i=index: tasks.append(asyncio.ensure_future(play(i, t))))
            await pc.setLocalDescription(await pc.createOffer())
            reply = await http.post(
                f"/webrtc?video={CAMERA}",
                content=pc.localDescription.sdp,
                headers={"Content-Type": "application/sdp"},
            )
            assert reply.status_code == 201, reply.text
            await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
            pcs.append(pc)
    await asyncio.sleep(SETTLE_S)
    before, frames_before = proc_stats(pid).cpu_s, sum(got)
    started = time.monotonic()
    await asyncio.sleep(seconds)
    cpu = proc_stats(pid).cpu_s - before
    wall = time.monotonic() - started
    frames = sum(got) - frames_before
    for pc in pcs:
        await pc.close()
    for task in tasks:
        task.cancel()
    return {
        "viewers": count,
        "server_cpu_percent": round(100 * cpu / wall, 1),
        "frames_per_s_per_viewer": round(frames / wall / max(count, 1), 1),
    }


def cpu_rows(seconds: float, viewers: int) -> list[dict[str, object]]:
    """The server's CPU with 0, 1 and ``viewers`` players, per codec; one server each."""
    from .servers import rwt_pythonpath  # noqa: PLC0415

    rows: list[dict[str, object]] = []
    for codec in ("video/VP8", "video/H264"):
        env = dict(os.environ, PYTHONPATH=rwt_pythonpath(), PYTHONUNBUFFERED="1")
        robot = subprocess.Popen(
            [sys.executable, "-m", "benchmarks.webrtc_video", "robot"],
            stdout=subprocess.PIPE,
            env=env,
            text=True,
        )
        try:
            assert robot.stdout is not None
            line = robot.stdout.readline()
            assert line.startswith("listening on ws://"), line
            base = line.split()[-1].replace("ws://", "http://")
            cases = [
                asyncio.run(_watch(base, count, codec, seconds, robot.pid))
                for count in (0, 1, viewers)
            ]
        finally:
            robot.send_signal(signal.SIGINT)
            robot.wait(10)
        none, one, many = (c["server_cpu_percent"] for c in cases)
        rows.append(
            {
                "codec": codec,
                "cases": cases,
                "stream_cpu_percent": round(one - none, 1),
                "extra_viewer_cpu_percent": round((many - one) / (viewers - 1), 1),
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("role", nargs="?", default="bench", choices=["bench", "robot"])
    parser.add_argument("--frames", type=int, default=900)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--viewers", type=int, default=4)
    parser.add_argument("--quick", action="store_true", help="30 frames, 3 s a case")
    args = parser.parse_args()
    if args.role == "robot":
        import anyio  # noqa: PLC0415

        anyio.run(_robot)
        return
    frames, seconds = (30, 3.0) if args.quick else (args.frames, args.seconds)
    result = {
        "frames": frames,
        "load_at_start": os.getloadavg()[0],
        "bandwidth": bandwidth_rows(frames),
        "cpu": cpu_rows(seconds, args.viewers),
    }
    print(json.dumps(result, indent=1))
    if not args.quick:
        RESULTS.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
