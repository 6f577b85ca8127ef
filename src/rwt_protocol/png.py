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

from .errors import RemoteProtocolError

__all__ = ["decode_png", "encode_png", "png_dimensions"]

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


def decode_png(text: str, *, max_bytes: int) -> bytes:
    r"""Unpack the bytes carried by a base64 PNG (the inverse of ``encode_png``).

    Args:
        text: standard base64 of a PNG file.
        max_bytes: the largest pixel payload accepted (``--max-message-size``).

    Returns:
        The pixel bytes without trailing ``\\n``/NUL padding.

    Raises:
        RemoteProtocolError: not base64, not a PNG, a mode other than 8-bit
            L/RGB/RGBA, more than ``max_bytes`` of pixels, or a corrupt file.
    """
    from PIL import Image  # noqa: PLC0415 (see encode_png)

    try:
        raw = binascii.a2b_base64(text, strict_mode=True)
    except ValueError:  # binascii.Error, or a non-ASCII character in the text
        raise RemoteProtocolError("data is not valid base64") from None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            image = Image.open(io.BytesIO(raw), formats=["PNG"])
    except Image.DecompressionBombError:
        raise RemoteProtocolError(f"PNG holds more than {max_bytes} bytes") from None
    except (OSError, ValueError, SyntaxError):
        raise RemoteProtocolError("data is not a valid PNG image") from None
    with image:
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
        try:
            pixels = image.tobytes()
        except (OSError, ValueError, SyntaxError):
            raise RemoteProtocolError("data is not a valid PNG image") from None
    return pixels.rstrip(b"\n\x00")
