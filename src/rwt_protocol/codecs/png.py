r"""PNG compression of op texts (spec 3.1.2, D20, REF §3.3).

The Robot Web Tools paper (section IV.D) packs the JSON text of a message into
the pixels of an RGB image so that browsers can inflate it with their built-in
PNG decoder. The layout is REF §3.3's, byte for byte: for L bytes of UTF-8 JSON,
width = floor(sqrt(L/3)), height = ceil(L/3/width), padded with ``\\n`` (JSON
whitespace) to width*height*3 bytes, saved by Pillow with its default settings,
then base64 (standard alphabet, padded).

Decoding accepts any 8-bit grayscale, RGB or RGBA PNG (Pillow undoes every PNG
filter type) and strips trailing padding (``\\n``, and the NUL bytes the paper's
description pads with). The image size is checked against a byte limit before
any pixel is inflated, so a small PNG cannot expand beyond it.
"""

from __future__ import annotations

import base64
import binascii
import io
import math
import warnings
from typing import TYPE_CHECKING

from ..errors import RemoteProtocolError

if TYPE_CHECKING:
    from PIL.ImageFile import ImageFile

__all__ = ["PendingPng", "decode_png", "encode_png", "png_dimensions", "read_png"]

_BANDS = {"L": 1, "RGB": 3, "RGBA": 4}
_PAD = b"\n"


def png_dimensions(length: int) -> tuple[int, int]:
    """The ``(width, height)`` of the image that holds ``length`` bytes (REF §3.3).

    ``length`` below 3 gives a 1-pixel-wide image (the reference divides by zero).
    """
    pixels = length / 3
    width = max(1, math.floor(math.sqrt(pixels)))
    height = max(1, math.ceil(pixels / width))
    return width, height


def encode_png(data: bytes) -> str:
    """Pack ``data`` (UTF-8 JSON text) into a PNG image, base64-encoded.

    Args:
        data: the bytes to carry, usually the JSON text of one op.

    Returns:
        The standard, padded base64 of the PNG file (the ``data`` of a ``png`` op).
    """
    from PIL import Image  # noqa: PLC0415 (Pillow loads with the first png op: benchmarks B11)

    width, height = png_dimensions(len(data))
    padded = data + _PAD * (width * height * 3 - len(data))
    image = Image.frombytes("RGB", (width, height), padded)
    out = io.BytesIO()
    image.save(out, format="PNG")
    return base64.b64encode(out.getbuffer()).decode("ascii")


class PendingPng:
    """A PNG whose header was checked and whose pixels are not inflated yet.

    Made by ``read_png``; ``inflate`` does the costly part, and touches nothing
    but this object, so a transport may run it in a worker thread (docs/limits.md).

    Attributes:
        pixel_bytes: the bytes ``inflate`` makes (width x height x bands), known
            from the header: what the inflating costs its sender.
    """

    __slots__ = ("_raw", "pixel_bytes")

    def __init__(self, raw: bytes, pixel_bytes: int) -> None:
        self._raw = raw
        self.pixel_bytes = pixel_bytes

    def inflate(self) -> bytes:
        r"""The pixel bytes without trailing ``\n``/NUL padding.

        Raises:
            RemoteProtocolError: the compressed data is corrupt.
        """
        image = _open(self._raw, self.pixel_bytes)
        with image:
            try:
                pixels = image.tobytes()
            except (OSError, ValueError, SyntaxError):
                raise RemoteProtocolError("data is not a valid PNG image") from None
        return pixels.rstrip(b"\n\x00")


def _open(raw: bytes, max_bytes: int) -> ImageFile:
    """Open ``raw`` as a PNG (header only); Pillow's own bomb check reads as ``max_bytes``'."""
    from PIL import Image  # noqa: PLC0415 (see encode_png)

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            return Image.open(io.BytesIO(raw), formats=["PNG"])
    except Image.DecompressionBombError:
        raise RemoteProtocolError(f"PNG holds more than {max_bytes} bytes") from None
    except (OSError, ValueError, SyntaxError):
        raise RemoteProtocolError("data is not a valid PNG image") from None


def read_png(text: str, *, max_bytes: int) -> PendingPng:
    """Check a base64 PNG up to its header, without inflating any pixel.

    Args:
        text: standard base64 of a PNG file.
        max_bytes: the largest pixel payload accepted (``--max-message-size``).

    Returns:
        The PNG, to ``inflate``, with its ``pixel_bytes``.

    Raises:
        RemoteProtocolError: not base64, not a PNG, a mode other than 8-bit
            L/RGB/RGBA, or more than ``max_bytes`` of pixels.
    """
    try:
        raw = binascii.a2b_base64(text, strict_mode=True)
    except ValueError:  # binascii.Error, or a non-ASCII character in the text
        raise RemoteProtocolError("data is not valid base64") from None
    with _open(raw, max_bytes) as image:
        bands = _BANDS.get(image.mode)
        if bands is None:
            raise RemoteProtocolError(
                f"expected an 8-bit L, RGB or RGBA PNG, got mode {image.mode}"
            )
        width, height = image.size
    if width * height * bands > max_bytes:
        raise RemoteProtocolError(
            f"PNG of {width}x{height} {image.mode} holds more than {max_bytes} bytes"
        )
    return PendingPng(raw, width * height * bands)


def decode_png(text: str, *, max_bytes: int) -> bytes:
    r"""Unpack the bytes carried by a base64 PNG (the inverse of ``encode_png``).

    ``read_png`` then ``inflate``, at once.

    Args:
        text: standard base64 of a PNG file.
        max_bytes: the largest pixel payload accepted (``--max-message-size``).

    Returns:
        The pixel bytes without trailing ``\n``/NUL padding.

    Raises:
        RemoteProtocolError: not base64, not a PNG, a mode other than 8-bit
            L/RGB/RGBA, more than ``max_bytes`` of pixels, or a corrupt file.
    """
    return read_png(text, max_bytes=max_bytes).inflate()
