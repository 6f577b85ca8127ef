"""What a ``/stream`` or ``/snapshot`` URL asks for, with web_video_server's defaults.

Query parameters and defaults follow web_video_server (REFERENCE: its
``ImageTransportImageStreamer``, ``MjpegStreamer``, ``PngStreamer`` and
``LibavStreamer``): ``type`` (mjpeg), ``quality`` (95 for JPEG, PNG
compression level 3 for png), ``width``/``height`` (-1: the image's own),
``invert`` (present: rotate 180 degrees), ``bitrate`` (100000 bit/s), ``qmin``
(10), ``qmax`` (42) and ``gop`` (25) for the video codecs. Two requests with the
same ``StreamParams`` share one encoder.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum
from typing import TYPE_CHECKING

from rwt_protocol.errors import RwtError

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = [
    "MAX_BITRATE",
    "MAX_GOP",
    "MAX_PIXELS",
    "MAX_SIDE",
    "StreamParamError",
    "StreamParams",
    "StreamType",
    "VideoError",
    "parse_stream_params",
]

MAX_SIDE = 4096
"""The largest ``width`` or ``height`` a request may ask for, pixels (docs/limits.md)."""

MAX_PIXELS = 3840 * 2160
"""The most pixels of one output frame (4K UHD), asked for or kept from the image:
an encoder holds a few frames of this size, so this bounds its memory (docs/limits.md)."""

MAX_BITRATE = 100_000_000
"""The highest video ``bitrate``, bit/s (docs/limits.md)."""

MAX_GOP = 1000
"""The longest keyframe interval ``gop``, frames (docs/limits.md)."""


class StreamType(StrEnum):
    """The ``type`` values web_video_server serves."""

    MJPEG = "mjpeg"
    PNG = "png"
    ROS_COMPRESSED = "ros_compressed"
    VP8 = "vp8"
    VP9 = "vp9"
    H264 = "h264"

    @property
    def is_video(self) -> bool:
        """Encoded by a video codec into a container (PyAV), not frame by frame."""
        return self in (StreamType.VP8, StreamType.VP9, StreamType.H264)


class VideoError(RwtError):
    """Root of the video server's errors."""


class StreamParamError(VideoError):
    """A query parameter that cannot be used; ``status`` is the HTTP status to answer."""

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class StreamParams:
    """One stream's settings; equal params mean one shared encoder.

    Attributes:
        topic: the image topic (resolved, with a leading slash).
        type: the encoding.
        quality: JPEG quality 1..100, or the PNG compression level 0..9.
        width, height: output size in pixels; -1 keeps the image's.
        invert: rotate by 180 degrees.
        bitrate: target video bit rate, bit/s.
        qmin, qmax: video quantiser bounds.
        gop: video keyframe interval, frames.
    """

    topic: str
    type: StreamType = StreamType.MJPEG
    quality: int = 95
    width: int = -1
    height: int = -1
    invert: bool = False
    bitrate: int = 100_000
    qmin: int = 10
    qmax: int = 42
    gop: int = 25

    @property
    def source_topic(self) -> str:
        """The topic subscribed: ``<topic>/compressed`` for ros_compressed (image_transport)."""
        if self.type is StreamType.ROS_COMPRESSED:
            return f"{self.topic.rstrip('/')}/compressed"
        return self.topic

    def with_type(self, stream_type: StreamType) -> StreamParams:
        """The same stream as another type (ros_compressed falls back to mjpeg)."""
        return replace(self, type=stream_type, quality=_default_quality(stream_type, None))


def parse_stream_params(
    query: Mapping[str, str], default_type: StreamType = StreamType.MJPEG
) -> StreamParams:
    """Read a request's query parameters.

    Args:
        query: the decoded query (last value of each name).
        default_type: used when ``type`` is absent (web_video_server's
            ``default_stream_type``).

    Returns:
        The parameters; parameters a type does not use keep their defaults so
        that they do not split one stream into several.

    Raises:
        StreamParamError: no ``topic`` (400), an unknown ``type`` (404, as
            web_video_server), or a number that is not an integer or out of range (400):
            ``width``/``height`` over ``MAX_SIDE`` or their product over
            ``MAX_PIXELS``, ``bitrate`` over ``MAX_BITRATE``, ``gop`` over ``MAX_GOP``,
            ``qmin`` over ``qmax`` (docs/limits.md).
    """
    topic = query.get("topic", "")
    if not topic:
        raise StreamParamError("missing query parameter topic")
    try:
        stream_type = StreamType(query.get("type", default_type.value))
    except ValueError:
        raise StreamParamError(f"unknown stream type {query.get('type')!r}", status=404) from None
    params = StreamParams(
        topic=topic if topic.startswith("/") else f"/{topic}",
        type=stream_type,
        quality=_default_quality(stream_type, query),
        width=_int(query, "width", -1, low=-1, high=MAX_SIDE),
        height=_int(query, "height", -1, low=-1, high=MAX_SIDE),
        invert="invert" in query,
    )
    if stream_type.is_video:
        params = replace(
            params,
            bitrate=_int(query, "bitrate", 100_000, low=1, high=MAX_BITRATE),
            qmin=_int(query, "qmin", 10, low=0, high=63),
            qmax=_int(query, "qmax", 42, low=0, high=63),
            gop=_int(query, "gop", 25, low=1, high=MAX_GOP),
        )
        if params.qmin > params.qmax:
            raise StreamParamError(f"qmin={params.qmin} is above qmax={params.qmax}")
    if params.width == 0 or params.height == 0:
        raise StreamParamError("width and height must be positive (or -1 for the image's)")
    if params.width * params.height > MAX_PIXELS:
        raise StreamParamError(f"width x height is over {MAX_PIXELS} pixels")
    return params


def _default_quality(stream_type: StreamType, query: Mapping[str, str] | None) -> int:
    if stream_type is StreamType.MJPEG:
        return _int(query or {}, "quality", 95, low=1, high=100)
    if stream_type is StreamType.PNG:
        return _int(query or {}, "quality", 3, low=0, high=9)
    return 0  # not used by this type


def _int(query: Mapping[str, str], name: str, default: int, *, low: int, high: int) -> int:
    raw = query.get(name)
    if raw is None or raw == "":
        return default
    # int() parses at most 4300 digits; anything longer than 12 is out of range anyway
    if len(raw) > 12 or not raw.lstrip("-").isdigit() or not raw.isascii():
        shown = raw if len(raw) <= 20 else raw[:17] + "..."
        raise StreamParamError(f"{name}={shown!r} is not an integer in {low}..{high}")
    value = int(raw)
    if not low <= value <= high:
        raise StreamParamError(f"{name}={value} is outside {low}..{high}")
    return value
