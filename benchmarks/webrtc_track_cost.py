"""The robot's CPU per viewer of a WebRTC video track: aiortc against libdatachannel (D51).

One pre-encoded H.264 stream (640x480 at 30 frames a second, libx264 baseline,
zerolatency, 1 Mbit/s, a key frame a second: what the tracks' shared encoder hands every
viewer of a topic, encoded once) is sent to N viewers from a "robot" process, on each
stack in turn:

- **aiortc**: a peer connection per viewer answering its offer, the track yielding the
  encoded packets (``av.Packet``) as rwt's ``webrtc.video.VideoTrack`` does, so aiortc
  only cuts them into RTP packets, encrypts them (SRTP) and paces them, in Python;
- **native**: libdatachannel (``libdatachannel-py``), a peer connection per viewer, the
  offered track with libdatachannel's H.264 packetizer, RTCP sender reports and NACK
  responder, the frames handed over with ``send_frame`` from one thread at 30 Hz.

With ``--through rwt`` the robot is rwt's own server instead (``RosbridgeServer`` with
``WebRtcOptions(stack=...)``, a 640x480 ``sensor_msgs/msg/Image`` camera at 30 Hz on its
graph), and each viewer posts its offer to ``/webrtc?video=/camera/image`` preferring
H.264: the whole path, its shared encoder included (paid once whatever the viewers, so
the difference between the stacks is the viewers' cost). On the native stack
libdatachannel sends the track (``webrtc/native_video.py``), on aiortc aiortc does.

The viewers are aiortc peers in another process (receive only, H.264, decoding each
frame); the table gives the robot process's CPU (every thread, from ``/proc``) while
they watch, in % of a core and per viewer, and the frames a second each viewer decoded.
The encoding is not in it: it is paid once per topic whatever the stack. What it
answers: whether moving the video tracks to the native stack would make a viewer
cheaper for the robot (issue's "video where it is cheapest").

Run (Python 3.12+ with the ``webrtc`` extra, both stacks):
``python -m benchmarks.webrtc_track_cost [--viewers 1,4,8] [--seconds 8] [--through rwt]``.
``--codec VP8``: the stream and the viewers are VP8 (libvpx); on the native stack the
packets are made as rwt makes them there (``webrtc.native_video.Vp8Rtp``: aiortc's VP8
payloader, libdatachannel's SRTP, reports and NACK responder).
Results: ``results/webrtc_track_cost.json`` (``webrtc_track_cost_rwt.json`` through rwt;
``_vp8`` before ``.json`` with VP8).
"""

from __future__ import annotations

import argparse
import asyncio
import fractions
import json
import multiprocessing
import os
import threading
import time
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results" / "webrtc_track_cost.json"
RESULTS_RWT = RESULTS.with_name("webrtc_track_cost_rwt.json")
CAMERA = "/camera/image"
FPS = 30
WARMUP_S = 2.0
STACKS = ("native", "aiortc")


def encode(count: int = FPS * 4, name: str = "H264") -> list[bytes]:
    """``count`` H.264 access units (Annex B) or VP8 frames of a moving synthetic picture."""
    import av  # noqa: PLC0415 (the webrtc extra)

    codec = av.CodecContext.create("libx264" if name == "H264" else "libvpx", "w")
    codec.width, codec.height, codec.pix_fmt = 640, 480, "yuv420p"
    codec.framerate = fractions.Fraction(FPS, 1)
    codec.bit_rate = 1_000_000
    codec.options = (
        {"tune": "zerolatency", "profile": "baseline", "g": str(FPS)}
        if name == "H264"
        else {"deadline": "realtime", "cpu-used": "8", "lag-in-frames": "0", "g": str(FPS)}
    )
    units = []
    for index in range(count):
        frame = av.VideoFrame(640, 480, "yuv420p")
        for plane, height in zip(frame.planes, (480, 240, 240), strict=True):
            row = bytes((x * 3 + index * 7) % 256 for x in range(plane.line_size))
            plane.update(b"".join(row[y % 97 :] + row[: y % 97] for y in range(height)))
        frame.pts, frame.time_base = index, fractions.Fraction(1, FPS)
        units += [bytes(packet) for packet in codec.encode(frame)]
    return units


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _viewers(
    pipe: Any, count: int, seconds: float, server: str | None = None, codec: str = "H264"
) -> None:
    """``count`` aiortc viewers: offers out, answers in, then frames decoded a second each.

    ``server``: rwt's HTTP base URL, where each offer is posted; None: over ``pipe``.
    ``codec``: the one the viewers offer (``H264``, or ``VP8`` through rwt).
    """

    async def main() -> None:
        from aiortc import RTCPeerConnection, RTCSessionDescription  # noqa: PLC0415
        from aiortc.rtcrtpsender import RTCRtpSender  # noqa: PLC0415

        counts = [0] * count
        peers = []
        h264 = [c for c in RTCRtpSender.getCapabilities("video").codecs if codec in c.mimeType]
        for index in range(count):
            peer = RTCPeerConnection()
            peer.addTransceiver("video", direction="recvonly").setCodecPreferences(h264)

            @peer.on("track")
            def on_track(track: Any, index: int = index) -> None:
                async def read() -> None:
                    while True:
                        try:
                            await track.recv()
                        except Exception:  # the track ended
                            return
                        counts[index] += 1

                asyncio.ensure_future(read())  # noqa: RUF006 (ends with the track)

            await peer.setLocalDescription(await peer.createOffer())
            peers.append(peer)
        offers = [peer.localDescription.sdp for peer in peers]
        answers = await _posted(server, offers) if server else None
        if answers is None:
            pipe.send(offers)
            answers = pipe.recv()
        for peer, answer in zip(peers, answers, strict=True):
            await peer.setRemoteDescription(RTCSessionDescription(answer, "answer"))
        await asyncio.sleep(WARMUP_S)
        before = list(counts)
        pipe.send("go")
        await asyncio.sleep(seconds)
        pipe.send([(after - first) / seconds for after, first in zip(counts, before, strict=True)])
        for peer in peers:
            await peer.close()

    asyncio.run(main())


async def _answer_aiortc(offers: list[str], units: list[bytes]) -> tuple[list[Any], list[str]]:
    import av  # noqa: PLC0415
    from aiortc import MediaStreamTrack, RTCPeerConnection, RTCSessionDescription  # noqa: PLC0415

    class Packets(MediaStreamTrack):
        """The encoded stream at 30 Hz, as ``webrtc.video.VideoTrack`` hands aiortc packets."""

        kind = "video"

        def __init__(self) -> None:
            super().__init__()
            self.index = 0
            self.start: float | None = None

        async def recv(self) -> Any:
            self.start = self.start or time.monotonic()
            await asyncio.sleep(max(0.0, self.start + self.index / FPS - time.monotonic()))
            packet = av.Packet(units[self.index % len(units)])
            packet.pts, packet.time_base = self.index * 90000 // FPS, fractions.Fraction(1, 90000)
            self.index += 1
            return packet

    peers, answers = [], []
    for sdp in offers:
        peer = RTCPeerConnection()
        await peer.setRemoteDescription(RTCSessionDescription(sdp, "offer"))
        transceiver = peer.getTransceivers()[0]
        transceiver.sender.replaceTrack(Packets())
        transceiver.direction = "sendonly"
        await peer.setLocalDescription(await peer.createAnswer())
        answers.append(peer.localDescription.sdp)
        peers.append(peer)
    return peers, answers


def _answer_native(offers: list[str], name: str) -> tuple[list[Any], list[Any], list[str]]:
    """libdatachannel's answers; each track with its VP8 packetizer (None for H.264)."""
    import libdatachannel as ldc  # noqa: PLC0415 (Python 3.12+)

    from rwt_transports.webrtc.native_video import Vp8Rtp  # noqa: PLC0415

    peers, tracks, answers = [], [], []
    for index, sdp in enumerate(offers):
        peer = ldc.PeerConnection(ldc.Configuration())
        offered: list[Any] = []
        peer.on_track(offered.append)
        peer.set_remote_description(ldc.Description(sdp, ldc.Description.Type.Offer))
        while peer.gathering_state() != ldc.PeerConnection.GatheringState.Complete:
            time.sleep(0.005)
        answers.append(str(peer.local_description()))
        track = offered[0]
        media = track.description()
        kind = next(p for p in media.payload_types() if media.rtp_map(p).format == name)
        config = ldc.RtpPacketizationConfig(1000 + index, f"robot{index}", kind, 90000)
        rtp = None
        if name == "H264":
            track.set_media_handler(
                ldc.H264RtpPacketizer(ldc.NalUnit.Separator.LongStartSequence, config)
            )
            track.chain_media_handler(ldc.RtcpSrReporter(config))
        else:  # rwt's VP8 path on this stack: aiortc's payloader, libdatachannel's chain
            rtp = Vp8Rtp(1000 + index, kind, track.mid(), None)
            track.set_media_handler(ldc.RtcpSrReporter(config))
        track.chain_media_handler(ldc.RtcpNackResponder())
        peers.append(peer)
        tracks.append((track, rtp))
    return peers, tracks, answers


async def _posted(server: str, offers: list[str]) -> list[str]:
    """Each offer posted to rwt's ``/webrtc?video=``: the answers."""
    import httpx  # noqa: PLC0415

    answers = []
    async with httpx.AsyncClient(base_url=server, timeout=30) as http:
        for offer in offers:
            reply = await http.post(
                f"/webrtc?video={CAMERA}",
                content=offer,
                headers={"Content-Type": "application/sdp"},
            )
            reply.raise_for_status()
            answers.append(reply.text)
    return answers


def _frames(count: int = FPS) -> list[Any]:
    """``count`` 640x480 rgb8 pictures of a moving pattern (numpy)."""
    import numpy as np  # noqa: PLC0415

    x = np.arange(640, dtype=np.uint16)[None, :]
    y = np.arange(480, dtype=np.uint16)[:, None]
    frames = []
    for i in range(count):
        planes = [(x * 3 + y + i * 7) % 256, (y * 2 + x + i * 5) % 256, (x + y * 3) % 256]
        frames.append(np.stack(planes, axis=-1).astype(np.uint8))
    return frames


def _rwt(stack: str, pipe: Any, out: Any, name: str = "H264") -> None:
    """rwt's server on ``stack`` with a 30 Hz camera: its URL out, then its CPU share."""
    import anyio  # noqa: PLC0415

    from rwt import Graph, RosbridgeServer, ServerConfig  # noqa: PLC0415
    from rwt_graph.media import array_to_image  # noqa: PLC0415
    from rwt_transports.webrtc.signalling import WebRtcOptions  # noqa: PLC0415

    frames = _frames()

    async def main() -> None:
        graph = Graph()
        config = ServerConfig(host="127.0.0.1", port=0, webrtc=WebRtcOptions(stack=stack))
        server = RosbridgeServer(graph, config)
        publisher = graph.create_publisher(CAMERA, "sensor_msgs/msg/Image", node="/camera")

        async def camera() -> None:
            start = time.monotonic()
            for index in range(10**9):
                publisher.publish(array_to_image(frames[index % len(frames)], "rgb8"))
                await anyio.sleep(max(0.0, start + (index + 1) / FPS - time.monotonic()))

        async with anyio.create_task_group() as tg:
            tg.start_soon(camera)
            url = await tg.start(server.serve)
            pipe.send(str(url).replace("ws://", "http://"))
            await anyio.to_thread.run_sync(pipe.recv)  # "go"
            cpu, start = _cpu_s(os.getpid()), time.monotonic()
            fps = await anyio.to_thread.run_sync(pipe.recv)
            out.send(((_cpu_s(os.getpid()) - cpu) / (time.monotonic() - start), fps))
            server.stop()
            tg.cancel_scope.cancel()

    anyio.run(main)


def _robot(stack: str, pipe: Any, out: Any, name: str = "H264") -> None:
    """Answer the viewers' offers on ``stack``, send to them, report CPU share and their fps."""
    units = encode(name=name)
    offers = pipe.recv()
    if stack == "aiortc":

        async def main() -> None:
            peers, answers = await _answer_aiortc(offers, units)
            pipe.send(answers)
            await asyncio.get_running_loop().run_in_executor(None, pipe.recv)  # "go"
            cpu, start = _cpu_s(os.getpid()), time.monotonic()
            fps = await asyncio.get_running_loop().run_in_executor(None, pipe.recv)
            out.send(((_cpu_s(os.getpid()) - cpu) / (time.monotonic() - start), fps))
            for peer in peers:
                await peer.close()

        asyncio.run(main())
        return
    import libdatachannel as ldc  # noqa: PLC0415

    from rwt_video.encoders import VideoPacket  # noqa: PLC0415

    peers, tracks, answers = _answer_native(offers, name)
    pipe.send(answers)
    stop = threading.Event()

    def send() -> None:
        index, start = 0, time.monotonic()
        while not stop.is_set():
            info = ldc.FrameInfo(index * 90000 // FPS)
            unit = units[index % len(units)]
            frame = VideoPacket(unit, index * 1000 // FPS, keyframe=index % FPS == 0)
            for track, rtp in tracks:
                if not track.is_open():
                    continue
                if rtp is None:
                    track.send_frame(unit, info)
                else:
                    for packet in rtp.packets(frame):
                        track.send(packet)
            index += 1
            time.sleep(max(0.0, start + index / FPS - time.monotonic()))

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    pipe.recv()  # "go"
    cpu, start = _cpu_s(os.getpid()), time.monotonic()
    fps = pipe.recv()
    out.send(((_cpu_s(os.getpid()) - cpu) / (time.monotonic() - start), fps))
    stop.set()
    sender.join()
    for peer in peers:
        peer.close()


def measure(
    stack: str, viewers: int, seconds: float, through: str = "bare", codec: str = "H264"
) -> dict[str, Any]:
    """One case: the robot's CPU (share of a core) and each viewer's frames a second.

    ``through``: ``bare`` (a robot process sending pre-encoded frames) or ``rwt``
    (rwt's server with a camera).
    """
    context = multiprocessing.get_context("spawn")
    to_viewers, to_robot = context.Pipe()
    mine, theirs = context.Pipe()
    robot = context.Process(
        target=_rwt if through == "rwt" else _robot, args=(stack, to_robot, theirs, codec)
    )
    robot.start()
    server = None
    if through == "rwt":
        if not to_viewers.poll(60):
            robot.kill()
            raise RuntimeError(f"rwt on {stack}: no URL")
        server = to_viewers.recv()
    viewer = context.Process(target=_viewers, args=(to_viewers, viewers, seconds, server, codec))
    viewer.start()
    procs = [viewer, robot]
    try:
        if not mine.poll(seconds + 60):
            raise RuntimeError(f"{stack} with {viewers} viewers: no result")
        share, fps = mine.recv()
    finally:
        for proc in procs:
            proc.join(30)
            if proc.is_alive():
                proc.kill()
    return {"stack": stack, "viewers": viewers, "cpu_share": share, "fps": fps, "codec": codec}


def table(rows: list[dict[str, Any]]) -> str:
    """The rows as Markdown; past one viewer, what each further viewer added (% of a core)."""
    one = {row["stack"]: row["cpu_share"] for row in rows if row["viewers"] == 1}
    lines = [
        "| viewers | stack | robot CPU, % of a core | per viewer | each viewer past the first "
        "| frames/s each (min) |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        n, share = row["viewers"], row["cpu_share"]
        extra = (
            f"{(share - one[row['stack']]) * 100 / (n - 1):.2f}"
            if n > 1 and row["stack"] in one
            else ""
        )
        lines.append(
            f"| {n} | {row['stack']} | {share * 100:.1f} | {share * 100 / n:.2f} | {extra} | "
            f"{min(row['fps']):.1f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Measure each viewer count on each stack, alternating; print and save the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--viewers", default="1,4,8", help="viewer counts, comma-separated")
    parser.add_argument("--seconds", type=float, default=8.0, help="each case's measurement")
    parser.add_argument("--stacks", default=",".join(STACKS))
    parser.add_argument("--out", type=Path, help="where the figures go (default: results/)")
    parser.add_argument(
        "--through",
        choices=("bare", "rwt"),
        default="bare",
        help="bare: the stacks alone; rwt: rwt's server with a camera, offers over HTTP",
    )
    parser.add_argument(
        "--codec", choices=("H264", "VP8"), default="H264", help="the viewers' codec"
    )
    parser.add_argument("--smoke", action="store_true", help="1 s a case, nothing saved")
    args = parser.parse_args(argv)
    seconds = 1.0 if args.smoke else args.seconds
    stacks = args.stacks.split(",")
    rows = []
    for round_index, viewers in enumerate(int(n) for n in args.viewers.split(",")):
        for stack in stacks if round_index % 2 == 0 else reversed(stacks):
            rows.append(measure(stack, viewers, seconds, args.through, args.codec))
    rows.sort(key=lambda row: (row["viewers"], row["stack"]))
    print(table(rows))
    if not args.smoke:
        default = RESULTS_RWT if args.through == "rwt" else RESULTS
        if args.codec == "VP8":
            default = default.with_name(default.stem + "_vp8.json")
        (args.out or default).write_text(json.dumps(rows, indent=2) + "\n", "utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
