"""A WHEP player made of aiortc: recvonly video transceivers, decoded frames (docs/webrtc.md).

Imported by the tests of this folder after their ``pytest.importorskip("aiortc")``.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import anyio
import av
import httpx
import numpy as np
from aiortc import (
    MediaStreamTrack,
    RTCConfiguration,
    RTCPeerConnection,
    RTCRtpReceiver,
    RTCSessionDescription,
)
from aiortc.mediastreams import MediaStreamError

from tests.webrtc.peer import RECEIVE_S, offer_sdp

SDP = {"Content-Type": "application/sdp"}


def image(width: int, height: int, rgb: tuple[int, int, int], stamp: int = 0) -> dict[str, object]:
    """A ``sensor_msgs/msg/Image`` (rgb8) of one colour."""
    pixels = np.empty((height, width, 3), np.uint8)
    pixels[...] = rgb
    return {
        "header": {"stamp": {"sec": stamp, "nanosec": 0}, "frame_id": "camera"},
        "height": height,
        "width": width,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": width * 3,
        "data": pixels.tobytes(),
    }


@dataclass
class Player:
    """A peer connection playing the server's video tracks; frames kept per track."""

    pc: RTCPeerConnection
    location: str
    answer: str
    frames: list[list[av.VideoFrame]] = field(default_factory=list)
    counts: list[int] = field(default_factory=list)
    arrived: anyio.Event = field(default_factory=anyio.Event)

    async def frame(self, track: int = 0, after: int = 0) -> av.VideoFrame:
        """The newest decoded frame of ``track`` once more than ``after`` have come."""
        with anyio.fail_after(RECEIVE_S):
            while self.counts[track] <= after:
                self.arrived = anyio.Event()
                await self.arrived.wait()
        return self.frames[track][-1]


def recvonly_offer(pc: RTCPeerConnection, tracks: int, codec: str) -> None:
    """Add ``tracks`` recvonly video transceivers preferring ``codec`` (``video/VP8``)."""
    capabilities = RTCRtpReceiver.getCapabilities("video")
    assert capabilities is not None
    chosen = [c for c in capabilities.codecs if c.mimeType == codec]
    for _ in range(tracks):
        pc.addTransceiver("video", direction="recvonly").setCodecPreferences(chosen)


async def post_offer(base: str, query: str, sdp: str, **headers: str) -> httpx.Response:
    """``POST /webrtc?<query>`` with ``sdp``."""
    async with httpx.AsyncClient(base_url=base) as http:
        return await http.post(f"/webrtc?{query}", content=sdp, headers={**SDP, **headers})


@asynccontextmanager
async def player(
    base: str, query: str, *, tracks: int = 1, codec: str = "video/VP8"
) -> AsyncIterator[Player]:
    """Offer ``tracks`` recvonly video transceivers (no data channel) to ``/webrtc?<query>``."""
    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    recvonly_offer(pc, tracks, codec)
    async with anyio.create_task_group() as tg:
        try:
            reply = await post_offer(base, query, await offer_sdp(pc))
            assert reply.status_code == 201, reply.text
            played = Player(pc, reply.headers["Location"], reply.text)
            played.frames = [[] for _ in range(tracks)]
            played.counts = [0] * tracks
            remote: list[MediaStreamTrack] = []
            pc.on("track", remote.append)
            await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
            for index, track in enumerate(remote):
                tg.start_soon(_play, played, index, track)
            yield played
        finally:
            tg.cancel_scope.cancel()
            with anyio.CancelScope(shield=True):
                await pc.close()


async def _play(played: Player, index: int, track: MediaStreamTrack) -> None:
    while True:
        try:
            frame = await track.recv()
        except MediaStreamError:
            return
        assert isinstance(frame, av.VideoFrame)
        played.frames[index] = [*played.frames[index][-2:], frame]  # the newest few
        played.counts[index] += 1
        played.arrived.set()
