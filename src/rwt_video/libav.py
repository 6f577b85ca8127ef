"""VP8 (WebM) and H.264 (fragmented MP4) through PyAV, the optional extra ``video``.

One codec context per stream encodes each frame once; every viewer gets its own
container (``VideoMuxer``) made from the encoder's stream as a template and fed
the shared packets from a keyframe on, so a viewer can join or resynchronise at
any keyframe. web_video_server instead runs one encoder per viewer.
"""

from __future__ import annotations

import contextlib
import fractions
import io
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import av
import av.container
import av.video
import av.video.stream
import numpy as np
from PIL import Image

from .encoders import EncodeError, Message, VideoPacket, prepare, stamp_seconds
from .params import StreamParams, StreamType

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["CODECS", "CODEC_THREADS", "PtsClock", "VideoEncoder", "VideoMuxer", "codec_options"]

_MS = fractions.Fraction(1, 1000)


@dataclass(frozen=True)
class _Codec:
    container: str
    codec: str
    content_type: str
    container_options: Mapping[str, str]


CODECS: Mapping[StreamType, _Codec] = {
    # live: no cues, no seeking back (web_video_server streams the same way)
    StreamType.VP8: _Codec("webm", "libvpx", "video/webm", {"live": "1"}),
    StreamType.VP9: _Codec("webm", "libvpx-vp9", "video/webm", {"live": "1"}),
    # fragmented MP4, one fragment per frame, so a browser can play it as it comes
    StreamType.H264: _Codec(
        "mp4",
        "libx264",
        "video/mp4",
        {"movflags": "frag_keyframe+frag_every_frame+empty_moov+default_base_moof"},
    ),
}


CODEC_THREADS = 1
"""Threads of one libvpx or libx264 encoder. Streams encode in parallel already (the
hub's ``ENCODER_THREADS``); FFmpeg's automatic count (one per CPU) made libvpx spend
17 to 77 ms of CPU on a frame of a 640x480 camera on a busy 2-core machine, against
7 ms with one thread (benchmarks/webrtc_video.py, benchmarks/JOURNAL.md)."""


def codec_options(params: StreamParams) -> dict[str, str]:
    """The options that run libvpx or libx264 in real time, with the bounds of ``params``.

    VP8 runs libvpx in real-time mode at its fastest setting, without lag or
    alt-ref frames, error-resilient (as web_video_server configures it); H.264
    runs libx264's ``ultrafast`` preset tuned for zero latency, without B-frames.
    """
    bounds = {"qmin": str(params.qmin), "qmax": str(params.qmax), "bf": "0"}
    if params.type in (StreamType.VP8, StreamType.VP9):
        return bounds | {
            "deadline": "realtime",
            "cpu-used": "8",
            "lag-in-frames": "0",
            "auto-alt-ref": "0",
            "error-resilient": "1",
        }
    return bounds | {"preset": "ultrafast", "tune": "zerolatency"}


class PtsClock:
    """Presentation times, ms from the first frame, from header stamps or arrival times.

    A stamp that advances gives the step; a stamp that does not (none, or repeated)
    is replaced by the arrival time, so the rate control sees the real frame rate.
    Times always advance by at least 1 ms.
    """

    def __init__(self) -> None:
        self._last: tuple[float, float, int] | None = None  # stamp, arrival, pts

    def pts(self, msg: Message) -> int:
        """The presentation time of ``msg``, ms."""
        stamp, now = stamp_seconds(msg), time.monotonic()
        if self._last is None:
            pts = 0
        else:
            last_stamp, last_now, last_pts = self._last
            step_s = stamp - last_stamp if stamp > last_stamp else now - last_now
            pts = last_pts + max(1, round(step_s * 1000))
        self._last = (stamp, now, pts)
        return pts


class VideoEncoder:
    """VP8 (WebM) or H.264 (fragmented MP4) through one PyAV codec context.

    The first frame fixes the output size (later frames are resized to it, as
    web_video_server does); video sizes are rounded down to even numbers, which
    4:2:0 chroma needs. Presentation times come from the header stamps, or from
    the arrival time where stamps do not advance, so the rate control sees the
    real frame rate. VP8 runs libvpx in real-time mode without lag or alt-ref
    frames, as web_video_server configures it.
    """

    def __init__(self, params: StreamParams) -> None:
        self.params = params
        self.codec = CODECS[params.type]
        self._lock = threading.Lock()  # the template stream is read by viewers' muxers
        self._master: av.container.OutputContainer | None = None
        self._stream: av.video.stream.VideoStream | None = None
        self._size: tuple[int, int] | None = None
        self._keyframe_requested = False
        self._clock = PtsClock()

    def request_keyframe(self) -> None:
        """Make the next frame a keyframe (a viewer joined or resynchronises)."""
        self._keyframe_requested = True

    def encode(self, msg: Message) -> list[VideoPacket]:
        """The packets the codec emits for ``msg`` (usually one).

        Raises:
            EncodeError: an unreadable image or a codec failure.
        """
        image = prepare(msg, self.params).convert("RGB")
        with self._lock:
            stream = self._open(image.width, image.height)
            if self._size != image.size:
                image = image.resize(self._size or image.size, Image.Resampling.BILINEAR)
            frame = av.VideoFrame.from_ndarray(np.asarray(image), format="rgb24")
            frame.pts = self._clock.pts(msg)
            frame.time_base = _MS
            if self._keyframe_requested:
                frame.pict_type = av.video.frame.PictureType.I
                self._keyframe_requested = False
            try:
                packets = stream.codec_context.encode(frame)
            except av.FFmpegError as exc:
                raise EncodeError(f"{self.codec.codec}: {exc}") from None
        return [VideoPacket(bytes(p), int(p.pts or 0), bool(p.is_keyframe)) for p in packets]

    def muxer(self) -> VideoMuxer:
        """A container for one viewer, to be fed packets from a keyframe on."""
        with self._lock:
            if self._stream is None:
                raise EncodeError("the encoder has not seen a frame yet")
            return VideoMuxer(self.codec, self._stream)

    def _open(self, width: int, height: int) -> av.video.stream.VideoStream:
        if self._stream is not None:
            return self._stream
        self._size = (max(2, width - width % 2), max(2, height - height % 2))
        master = av.open(
            _Collect(), "w", format=self.codec.container, options=dict(self.codec.container_options)
        )
        self._master = master  # owns the template stream; nothing is muxed into it
        stream = master.add_stream(self.codec.codec, rate=30)
        if not isinstance(stream, av.video.stream.VideoStream):
            raise EncodeError(f"{self.codec.codec} is not a video codec")
        context = stream.codec_context
        context.width, context.height = self._size
        context.pix_fmt = "yuv420p"
        context.time_base = _MS
        context.bit_rate = self.params.bitrate
        context.gop_size = self.params.gop
        context.thread_count = CODEC_THREADS
        context.options = codec_options(self.params)
        stream.time_base = _MS
        try:
            master.start_encoding()  # opens the codec with the container's flags
        except av.FFmpegError as exc:
            raise EncodeError(f"{self.codec.codec}: {exc}") from None
        self._stream = stream
        return stream


class VideoMuxer:
    """One viewer's container around the shared encoder's packets.

    The first packet must be a keyframe; times start at 0 for each viewer.
    ``add`` returns the container bytes produced so far (the muxers hold one
    frame back until the next arrives).
    """

    def __init__(self, codec: _Codec, template: av.video.stream.VideoStream) -> None:
        self._sink = _Collect()
        self._container: av.container.OutputContainer = av.open(
            self._sink, "w", format=codec.container, options=dict(codec.container_options)
        )
        self._stream = self._container.add_stream_from_template(template)
        self._stream.time_base = _MS
        self._base_ms: int | None = None

    def add(self, packet: VideoPacket) -> bytes:
        """Mux ``packet``; returns the bytes to send now (maybe none).

        Raises:
            EncodeError: the muxer refused the packet.
        """
        if self._base_ms is None:
            self._base_ms = packet.pts_ms
        copy = av.Packet(packet.data)
        copy.pts = copy.dts = packet.pts_ms - self._base_ms
        copy.time_base = _MS
        copy.is_keyframe = packet.keyframe
        copy.stream = self._stream
        try:
            self._container.mux(copy)
        except av.FFmpegError as exc:
            raise EncodeError(f"muxer: {exc}") from None
        return self._sink.take()

    def close(self) -> bytes:
        """Close the container; returns what it wrote last (the held frame, a trailer).

        A server drops these bytes: the viewer has gone.
        """
        with contextlib.suppress(Exception):  # after a muxer error it may fail again
            self._container.close()
        return self._sink.take()


class _Collect(io.RawIOBase):
    """A write-only, non-seekable file that keeps what is written until taken."""

    def __init__(self) -> None:
        super().__init__()
        self._chunks: list[bytes] = []

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return False

    def write(self, data: object) -> int:
        chunk = bytes(data)  # type: ignore[call-overload]
        self._chunks.append(chunk)
        return len(chunk)

    def take(self) -> bytes:
        out = b"".join(self._chunks)
        self._chunks.clear()
        return out
