"""``sensor_msgs/Image`` messages to numpy arrays and back.

The conversions follow what web_video_server does through cv_bridge
(REFERENCE: web_video_server ``ImageTransportImageStreamer::decodeImage``):
colour images become 8-bit RGB, 16-bit mono images are scaled to 8 bits, and
floating point images (``32FC1`` depth in metres) are scaled so that their
largest value maps to 255. ``16UC1`` (depth in millimetres) is scaled the same
way, since cv_bridge cannot show it at all and a fixed scale would leave a
depth image black.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from rwt_protocol.errors import GraphError

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = [
    "ImageError",
    "array_to_image",
    "compressed_content_type",
    "depth_to_metres",
    "image_to_array",
    "image_to_display",
]

U8Array = npt.NDArray[np.uint8]
F32Array = npt.NDArray[np.float32]


class ImageError(GraphError, ValueError):
    """An image that cannot be converted (unknown encoding, short data, bad shape).

    Also a ``ValueError``, as the depth-cloud codec's errors were.
    """


@dataclass(frozen=True)
class _Layout:
    dtype: str  # numpy dtype code without byte order
    channels: int
    bgr: bool = False  # the first three channels are blue, green, red


#: Encodings we read, by ``sensor_msgs/image_encodings`` name.
ENCODINGS: Mapping[str, _Layout] = {
    "rgb8": _Layout("u1", 3),
    "bgr8": _Layout("u1", 3, bgr=True),
    "rgba8": _Layout("u1", 4),
    "bgra8": _Layout("u1", 4, bgr=True),
    "mono8": _Layout("u1", 1),
    "8UC1": _Layout("u1", 1),
    "8UC3": _Layout("u1", 3, bgr=True),  # cv_bridge treats 8UC3 as BGR
    "8UC4": _Layout("u1", 4, bgr=True),
    "mono16": _Layout("u2", 1),
    "16UC1": _Layout("u2", 1),
    "32FC1": _Layout("f4", 1),
    "64FC1": _Layout("f8", 1),
}


def image_to_array(msg: Mapping[str, object]) -> npt.NDArray[np.generic]:
    """The pixels of an Image message as an array, without copying when possible.

    Args:
        msg: a ``sensor_msgs/Image`` in the internal form (``data`` as bytes).

    Returns:
        Shape (height, width) for one channel, (height, width, channels)
        otherwise; dtype from the encoding in native byte order; channels in
        message order (BGR stays BGR).

    Raises:
        ImageError: unknown encoding, zero size, or fewer bytes than
            ``step * height`` or a ``step`` shorter than a row.
    """
    encoding = str(msg.get("encoding", ""))
    layout = ENCODINGS.get(encoding)
    if layout is None:
        raise ImageError(f"unsupported image encoding {encoding!r}")
    height, width, step = _int(msg, "height"), _int(msg, "width"), _int(msg, "step")
    data = msg.get("data")
    if not isinstance(data, bytes | bytearray | memoryview):
        raise ImageError("image data is not bytes")
    dtype = np.dtype(layout.dtype).newbyteorder(">" if msg.get("is_bigendian") else "<")
    row_bytes = width * layout.channels * dtype.itemsize
    if height <= 0 or width <= 0:
        raise ImageError(f"empty image ({width}x{height})")
    if step < row_bytes or len(data) < step * (height - 1) + row_bytes:
        raise ImageError(
            f"{len(data)} bytes with step {step} do not hold a {width}x{height} {encoding} image"
        )
    rows = np.lib.stride_tricks.as_strided(
        np.frombuffer(data, dtype=np.uint8),
        shape=(height, row_bytes),
        strides=(step, 1),
        writeable=False,
    )
    pixels = np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="), copy=False)
    shape = (height, width) if layout.channels == 1 else (height, width, layout.channels)
    return pixels.reshape(shape)


def image_to_display(msg: Mapping[str, object], *, keep_alpha: bool = False) -> U8Array:
    """An Image message as 8-bit RGB (or RGBA) for JPEG, PNG and video encoders.

    Args:
        msg: a ``sensor_msgs/Image`` (see ``ENCODINGS`` for what is read).
        keep_alpha: return RGBA for encodings with alpha (web_video_server's PNG
            streams keep it); RGB otherwise.

    Returns:
        uint8 array of shape (height, width, 3) or (height, width, 4).

    Raises:
        ImageError: as ``image_to_array``.
    """
    encoding = str(msg.get("encoding", ""))
    pixels = image_to_array(msg)
    layout = ENCODINGS[encoding]
    if pixels.dtype.kind == "f" or encoding == "16UC1":
        gray = _scale_to_max(pixels.astype(np.float32))
    elif encoding == "mono16":
        gray = (pixels.astype(np.uint32) * 255 // 65535).astype(np.uint8)
    elif layout.channels == 1:
        gray = pixels.astype(np.uint8, copy=False)
    else:
        colour = pixels[..., [2, 1, 0, 3][: layout.channels]] if layout.bgr else pixels
        if not keep_alpha or layout.channels == 3:
            colour = colour[..., :3]
        return np.ascontiguousarray(colour, dtype=np.uint8)
    return np.repeat(gray[..., np.newaxis], 3, axis=2)


def depth_to_metres(msg: Mapping[str, object]) -> F32Array:
    """A depth image in metres: ``32FC1`` as is, ``16UC1``/``mono16`` millimetres / 1000.

    Holes stay as they are (NaN or 0); ``fill_depth_holes`` treats both as holes.

    Raises:
        ImageError: another encoding, or as ``image_to_array``.
    """
    encoding = str(msg.get("encoding", ""))
    pixels = image_to_array(msg)
    if encoding in ("32FC1", "64FC1"):
        return pixels.astype(np.float32, copy=False)
    if encoding in ("16UC1", "mono16"):
        return pixels.astype(np.float32) / np.float32(1000.0)
    raise ImageError(f"a depth image must be 32FC1 (m) or 16UC1 (mm), not {encoding!r}")


def array_to_image(
    pixels: npt.NDArray[np.generic],
    encoding: str,
    *,
    header: Mapping[str, object] | None = None,
) -> dict[str, object]:
    """An Image message (internal form) holding ``pixels``.

    Args:
        pixels: (height, width) or (height, width, channels) matching ``encoding``.
        encoding: one of ``ENCODINGS``; the caller's channel order is kept.
        header: the message header; missing means "stamp now" when published (D8).

    Raises:
        ImageError: unknown encoding or a shape or dtype that does not fit it.
    """
    layout = ENCODINGS.get(encoding)
    if layout is None:
        raise ImageError(f"unsupported image encoding {encoding!r}")
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    if pixels.ndim not in (2, 3) or channels != layout.channels:
        raise ImageError(f"shape {pixels.shape} does not fit {encoding}")
    if pixels.dtype != np.dtype(layout.dtype):
        raise ImageError(f"dtype {pixels.dtype} does not fit {encoding}")
    height, width = pixels.shape[:2]
    msg: dict[str, object] = {
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": width * channels * pixels.dtype.itemsize,
        "data": np.ascontiguousarray(pixels).astype(pixels.dtype.newbyteorder("<")).tobytes(),
    }
    if header is not None:
        msg["header"] = dict(header)
    return msg


def compressed_content_type(image_format: str) -> str | None:
    """The MIME type of a ``sensor_msgs/CompressedImage`` ``format``, if a browser shows it.

    As web_video_server's ros_compressed streamer: a format naming jpeg/jpg is
    ``image/jpeg``, png is ``image/png``, anything else None.
    """
    lowered = image_format.lower()
    if "jpeg" in lowered or "jpg" in lowered:
        return "image/jpeg"
    if "png" in lowered:
        return "image/png"
    return None


def _scale_to_max(values: F32Array) -> U8Array:
    """Scale so the largest finite value maps to 255; NaN and negatives become 0."""
    finite = np.where(np.isfinite(values), values, 0.0)
    top = float(finite.max(initial=0.0))
    if top > 0:
        finite = finite * (255.0 / top)
    return np.clip(finite, 0, 255).astype(np.uint8)


def _int(msg: Mapping[str, object], key: str) -> int:
    value = msg.get(key, 0)
    if not isinstance(value, int):
        raise ImageError(f"image {key} is not an integer")
    return value
