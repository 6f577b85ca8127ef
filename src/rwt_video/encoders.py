"""Frame encoders of the video server: JPEG, PNG, compressed pass-through, VP8 and H.264.

Each stream has one encoder, called from a worker thread with one message at a
time. Still-image encoders return a ``Part`` per frame (Pillow); video encoders
return ``VideoPacket``s from one PyAV codec context (libvpx, libx264), which each
viewer wraps in its own container (``VideoMuxer``) so that a viewer can join at
any keyframe (web_video_server encodes per viewer; here it is once per stream).
PyAV is the optional extra ``video``; without it the video types answer 501.
"""

from __future__ import annotations

import functools
import io
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from PIL import Image

from rwt_graph.media import ImageError, compressed_content_type, image_to_display
from rwt_graph.types.convert import header_stamp
from rwt_protocol.distribution import install_hint

from .params import MAX_PIXELS, StreamParams, StreamType, VideoError

__all__ = [
    "BOUNDARY",
    "VIDEO_CONTENT_TYPES",
    "EncodeError",
    "FrameEncoder",
    "Muxer",
    "Part",
    "VideoFrameEncoder",
    "VideoPacket",
    "make_encoder",
    "multipart_part",
    "stamp_seconds",
]

Message = Mapping[str, object]

BOUNDARY = "boundarydonotcross"  # web_video_server's multipart boundary

#: What a video stream's response holds.
VIDEO_CONTENT_TYPES: Mapping[StreamType, str] = {
    StreamType.VP8: "video/webm",
    StreamType.VP9: "video/webm",
    StreamType.H264: "video/mp4",
}


class EncodeError(VideoError):
    """A frame that cannot be encoded (bad image, codec failure); the frame is skipped."""


@dataclass(frozen=True)
class Part:
    """One encoded still image: a part of a multipart stream or a snapshot.

    Attributes:
        content_type: ``image/jpeg`` or ``image/png``.
        data: the encoded image.
        stamp_s: the message's header stamp, seconds (web_video_server's X-Timestamp).
    """

    content_type: str
    data: bytes
    stamp_s: float

    @functools.cached_property
    def multipart(self) -> bytes:
        """The part as a multipart stream sends it (``multipart_part``), made once.

        Every viewer of a stream sends these same bytes; the hub makes them in its
        encoder thread, so the event loop copies no image per viewer.
        """
        return multipart_part(self)


@dataclass(frozen=True)
class VideoPacket:
    """One encoded video frame.

    Attributes:
        data: the codec's packet.
        pts_ms: presentation time since the stream started, ms.
        keyframe: a viewer may start here.
    """

    data: bytes
    pts_ms: int
    keyframe: bool


def multipart_part(part: Part) -> bytes:
    r"""One part of web_video_server's ``multipart/x-mixed-replace`` stream.

    The stream starts with ``--BOUNDARY\\r\\n``; each part is its headers
    (Content-type, X-Timestamp, Content-Length), the image and the next boundary.
    """
    head = (
        f"Content-type: {part.content_type}\r\n"
        f"X-Timestamp: {part.stamp_s:.6f}\r\n"
        f"Content-Length: {len(part.data)}\r\n\r\n"
    )
    return b"".join((head.encode(), part.data, f"\r\n--{BOUNDARY}\r\n".encode()))


class FrameEncoder(Protocol):
    """Turns one message into what is sent to viewers (called from a worker thread)."""

    def encode(self, msg: Message) -> list[Part] | list[VideoPacket]:
        """Encode ``msg``; raises ``EncodeError`` for a frame to skip."""
        ...


class Muxer(Protocol):
    """One viewer's container around a video stream's packets."""

    def add(self, packet: VideoPacket) -> bytes:
        """Mux ``packet``; the bytes to send now. Raises ``EncodeError``."""
        ...

    def close(self) -> bytes:
        """Free the container; returns its last bytes."""
        ...


@runtime_checkable
class VideoFrameEncoder(Protocol):
    """A video encoder: viewers start at keyframes, each in its own container."""

    def encode(self, msg: Message) -> list[VideoPacket]:
        """Encode ``msg``; raises ``EncodeError`` for a frame to skip."""
        ...

    def request_keyframe(self) -> None:
        """Make the next frame a keyframe."""
        ...

    def muxer(self) -> Muxer:
        """A container for a new viewer. Raises ``EncodeError`` before the first frame."""
        ...


def make_encoder(params: StreamParams) -> FrameEncoder:
    """The encoder for ``params.type``.

    Raises:
        EncodeError: a video type without PyAV installed.
    """
    if params.type is StreamType.ROS_COMPRESSED:
        return CompressedPassThrough()
    if params.type.is_video:
        try:
            from .libav import VideoEncoder  # noqa: PLC0415  (PyAV is the optional extra)
        except ImportError:
            raise EncodeError(f"type={params.type} needs PyAV: {install_hint('video')}") from None
        return VideoEncoder(params)
    return StillEncoder(params)


def prepare(msg: Message, params: StreamParams, *, keep_alpha: bool = False) -> Image.Image:
    """The message as a Pillow image, inverted and resized as ``params`` ask.

    Like web_video_server, a missing width or height keeps the image's own.

    Raises:
        EncodeError: the image cannot be read, or the frame would be scaled up to
            more than ``params.MAX_PIXELS`` pixels (docs/limits.md).
    """
    try:
        pixels = image_to_display(msg, keep_alpha=keep_alpha)
    except ImageError as exc:
        raise EncodeError(str(exc)) from None
    image = Image.fromarray(pixels)
    if params.invert:
        image = image.transpose(Image.Transpose.ROTATE_180)
    size = (
        params.width if params.width > 0 else image.width,
        params.height if params.height > 0 else image.height,
    )
    if size[0] * size[1] > max(MAX_PIXELS, image.width * image.height):  # no upscaling past it
        raise EncodeError(f"a {size[0]}x{size[1]} frame is over {MAX_PIXELS} pixels")
    if size != image.size:
        image = image.resize(size, Image.Resampling.BILINEAR)
    return image


class StillEncoder:
    """JPEG (``mjpeg``, quality 1..100) or PNG (``png``, compression level 0..9) per frame."""

    def __init__(self, params: StreamParams) -> None:
        self.params = params

    def encode(self, msg: Message) -> list[Part]:
        """One ``Part`` for the frame; raises ``EncodeError`` for an unreadable image."""
        png = self.params.type is StreamType.PNG
        image = prepare(msg, self.params, keep_alpha=png)
        out = io.BytesIO()
        if png:
            image.save(out, "PNG", compress_level=self.params.quality)
        else:
            image.save(out, "JPEG", quality=self.params.quality)
        return [Part("image/png" if png else "image/jpeg", out.getvalue(), stamp_seconds(msg))]


class CompressedPassThrough:
    """``ros_compressed``: a ``sensor_msgs/CompressedImage`` sent as it is."""

    def encode(self, msg: Message) -> list[Part]:
        """The message's data; raises ``EncodeError`` for a format browsers do not show."""
        image_format = str(msg.get("format", ""))
        content_type = compressed_content_type(image_format)
        data = msg.get("data")
        if content_type is None or not isinstance(data, bytes):
            raise EncodeError(f"unknown compressed image format {image_format!r}")
        return [Part(content_type, data, stamp_seconds(msg))]


def stamp_seconds(msg: Message) -> float:
    """The message's header stamp in seconds (either dialect), 0.0 without one."""
    sec, nsec = header_stamp(msg) or (0, 0)
    return sec + nsec / 1e9
