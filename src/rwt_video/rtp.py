"""Frames for RTP: WebRTC video tracks encoded once per topic and codec (docs/webrtc.md).

The HTTP streams wrap their packets in a container per viewer (libav.py); an RTP
sender wants the bare bitstream instead, one frame at a time, which it cuts into
RTP packets itself: VP8 frames, and H.264 as Annex B (start codes, the SPS and
PPS before every IDR frame, Constrained Baseline as browsers and aiortc
negotiate it). So each ``VideoPacket`` here is one whole frame, and every peer
watching the topic in that codec sends the same bytes (the hub shares them).

The encoder runs libvpx or libx264 with the video server's real-time options
(``libav.codec_options``) and the stream's ``quality`` parameters (size,
``qmin``/``qmax``, ``gop``, ``bitrate``). Two things come from the peers:

- ``set_bitrate``: the receivers' estimates (REMB); the codec is reopened at the
  new rate when it differs by more than 10 % (libvpx and libx264 through FFmpeg
  take a new rate only when opened), at most every ``REOPEN_MIN_INTERVAL_S``,
  and never above the stream's ``bitrate`` nor below ``MIN_BITRATE``.
- ``request_keyframe``: a picture loss (PLI, FIR) or a peer that dropped a
  frame; at most one forced key frame per ``KEYFRAME_MIN_INTERVAL_S`` (a
  request in between is kept for the first frame after it), so a peer sending
  PLIs in a loop cannot turn every viewer's stream into key frames.

A ``sensor_msgs/CompressedImage`` topic in format ``h264`` is passed through
(``H264PassThrough``): its frames are sent as they are, key frames when the
source makes them.
"""

from __future__ import annotations

import fractions
import time
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import av
import av.video
import numpy as np
from PIL import Image

from .encoders import EncodeError, FrameEncoder, Message, Muxer, VideoPacket, prepare
from .libav import CODEC_THREADS, PtsClock, codec_options
from .params import StreamParams, StreamType

if TYPE_CHECKING:
    from av.video.codeccontext import VideoCodecContext

__all__ = [
    "KEYFRAME_MIN_INTERVAL_S",
    "MIN_BITRATE",
    "REOPEN_MIN_INTERVAL_S",
    "RTP_CODECS",
    "H264PassThrough",
    "RtpEncoder",
    "RtpFrameEncoder",
    "make_rtp_encoder",
]

KEYFRAME_MIN_INTERVAL_S = 0.5
"""Shortest time between two key frames forced by requests (PLI, FIR, a peer resuming), s."""

REOPEN_MIN_INTERVAL_S = 2.0
"""Shortest time between two bit-rate changes (each reopens the codec: a key frame), s."""

MIN_BITRATE = 50_000
"""The lowest bit rate a receiver's estimate sets, bit/s."""

RTP_CODECS = {StreamType.VP8: "libvpx", StreamType.H264: "libx264"}
"""The codecs a video track can be sent in, with the FFmpeg encoder of each."""

_MS = fractions.Fraction(1, 1000)
_COMPRESSED = "sensor_msgs/msg/CompressedImage"


@runtime_checkable
class RtpFrameEncoder(Protocol):
    """What a video track's shared stream encodes with.

    Attributes:
        frames: frames produced so far.
        keyframes: key frames among them.
    """

    frames: int
    keyframes: int

    def encode(self, msg: Message) -> list[VideoPacket]:
        """One frame for ``msg`` (none while the codec holds it); raises ``EncodeError``."""
        ...

    def request_keyframe(self) -> None:
        """Make a coming frame a key frame (bounded by ``KEYFRAME_MIN_INTERVAL_S``)."""
        ...

    def set_bitrate(self, bitrate: int) -> None:
        """The receivers' lowest estimate, bit/s."""
        ...

    def muxer(self) -> Muxer:
        """Never: RTP frames are not put in a container. Raises ``EncodeError``."""
        ...


class RtpEncoder:
    """VP8 or H.264 frames for RTP from ``sensor_msgs/Image`` messages, one codec context.

    Args:
        params: the stream: ``type`` (vp8 or h264), size, quantisers, ``gop``, and
            ``bitrate``, the highest rate, bit/s (the receivers' estimates lower it).

    Raises:
        EncodeError: ``params.type`` has no RTP codec here.
    """

    def __init__(self, params: StreamParams) -> None:
        if params.type not in RTP_CODECS:
            raise EncodeError(f"{params.type} cannot be sent over RTP")
        self.params = params
        self.target_bitrate = params.bitrate
        self.frames = 0
        self.keyframes = 0
        self.opened = 0
        self._context: VideoCodecContext | None = None
        self._opened_at = 0.0
        self._size: tuple[int, int] | None = None
        self._clock = PtsClock()
        self._keyframe_requested = False
        self._forced_at = -KEYFRAME_MIN_INTERVAL_S

    def request_keyframe(self) -> None:
        """Make the next frame a key frame, or the first one after ``KEYFRAME_MIN_INTERVAL_S``."""
        self._keyframe_requested = True

    def set_bitrate(self, bitrate: int) -> None:
        """Aim at ``bitrate`` bit/s, within ``MIN_BITRATE`` and the stream's ``bitrate``."""
        self.target_bitrate = max(MIN_BITRATE, min(bitrate, self.params.bitrate))

    def muxer(self) -> Muxer:
        """Raises ``EncodeError``: RTP frames are not put in a container."""
        raise EncodeError("RTP frames are not muxed")

    def encode(self, msg: Message) -> list[VideoPacket]:
        """The frame for ``msg``: one packet, or none while the codec holds it.

        Raises:
            EncodeError: an unreadable image or a codec failure.
        """
        image = prepare(msg, self.params).convert("RGB")
        if self._size is None:  # the first frame fixes the size; 4:2:0 needs even sides
            self._size = (
                max(2, image.width - image.width % 2),
                max(2, image.height - image.height % 2),
            )
        if image.size != self._size:
            image = image.resize(self._size, Image.Resampling.BILINEAR)
        now = time.monotonic()
        context = self._open(now)
        frame = av.VideoFrame.from_ndarray(np.asarray(image), format="rgb24")
        frame.pts = self._clock.pts(msg)
        frame.time_base = _MS
        if self._keyframe_requested and now - self._forced_at >= KEYFRAME_MIN_INTERVAL_S:
            frame.pict_type = av.video.frame.PictureType.I
            self._keyframe_requested = False
            self._forced_at = now
        try:
            packets = context.encode(frame)
        except av.FFmpegError as exc:
            raise EncodeError(f"{RTP_CODECS[self.params.type]}: {exc}") from None
        data = b"".join(bytes(p) for p in packets)
        if not data:
            return []
        keyframe = any(p.is_keyframe for p in packets)
        self.frames += 1
        self.keyframes += keyframe
        return [VideoPacket(data, int(frame.pts), keyframe)]

    def _open(self, now: float) -> VideoCodecContext:
        """The codec context, (re)opened at the target bit rate when it has moved."""
        context = self._context
        if context is not None:
            rate = context.bit_rate or self.target_bitrate
            moved = abs(self.target_bitrate - rate) > rate // 10
            if not moved or now - self._opened_at < REOPEN_MIN_INTERVAL_S:
                return context
        assert self._size is not None
        created = av.CodecContext.create(RTP_CODECS[self.params.type], "w")
        if not isinstance(created, av.video.codeccontext.VideoCodecContext):
            raise EncodeError(f"{RTP_CODECS[self.params.type]} is not a video codec")
        created.width, created.height = self._size
        created.pix_fmt = "yuv420p"
        created.time_base = _MS
        created.framerate = fractions.Fraction(30)
        created.bit_rate = self.target_bitrate
        created.gop_size = self.params.gop
        created.thread_count = CODEC_THREADS
        options = codec_options(self.params)
        if self.params.type is StreamType.H264:  # what browsers and aiortc negotiate
            options |= {"profile": "baseline"}
        created.options = options
        try:
            created.open()
        except av.FFmpegError as exc:
            raise EncodeError(f"{RTP_CODECS[self.params.type]}: {exc}") from None
        self._context, self._opened_at = created, now
        self.opened += 1
        return created


class H264PassThrough:
    """H.264 frames of a ``sensor_msgs/CompressedImage`` topic (format ``h264``), as they are.

    Each message must hold one access unit in Annex B (start codes); a key frame
    is one with an IDR slice. Nothing is re-encoded, so neither the receivers'
    estimates nor their key-frame requests reach the source.
    """

    def __init__(self) -> None:
        self.frames = 0
        self.keyframes = 0
        self._clock = PtsClock()

    def request_keyframe(self) -> None:
        """Nothing: the source decides where key frames are."""

    def set_bitrate(self, bitrate: int) -> None:
        """Nothing: the source decides the bit rate."""

    def muxer(self) -> Muxer:
        """Raises ``EncodeError``: RTP frames are not put in a container."""
        raise EncodeError("RTP frames are not muxed")

    def encode(self, msg: Message) -> list[VideoPacket]:
        """The message's frame.

        Raises:
            EncodeError: the message is not H.264 (its ``format``) or has no data.
        """
        image_format = str(msg.get("format", ""))
        data = msg.get("data")
        if "h264" not in image_format.lower() or not isinstance(data, bytes) or not data:
            raise EncodeError(f"a {image_format!r} image is not H.264: only h264 passes through")
        keyframe = _has_idr(data)
        self.frames += 1
        self.keyframes += keyframe
        return [VideoPacket(data, self._clock.pts(msg), keyframe)]


def _has_idr(data: bytes) -> bool:
    """Whether an Annex B access unit holds an IDR slice (NAL unit type 5)."""
    start = data.find(b"\x00\x00\x01")
    while start >= 0 and start + 3 < len(data):
        if data[start + 3] & 0x1F == 5:
            return True
        start = data.find(b"\x00\x00\x01", start + 3)
    return False


def make_rtp_encoder(params: StreamParams, type_name: str) -> FrameEncoder:
    """The shared encoder of one video track's stream (``hub.StreamHub``'s ``make``).

    Args:
        params: the stream (``type`` is the negotiated codec: vp8 or h264).
        type_name: the topic's type: a ``sensor_msgs/msg/Image`` is encoded, a
            ``sensor_msgs/msg/CompressedImage`` passed through (H.264 only).

    Raises:
        EncodeError: a compressed topic in another codec than H.264.
    """
    if type_name == _COMPRESSED:
        if params.type is not StreamType.H264:
            raise EncodeError(f"{params.topic} is compressed: only H.264 passes through")
        return H264PassThrough()
    return RtpEncoder(params)
