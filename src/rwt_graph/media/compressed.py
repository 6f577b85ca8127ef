"""Compressed images (JPEG, PNG) the server decodes: never more pixels than it can afford.

A ``sensor_msgs/CompressedImage`` is small on the wire and large decoded: a PNG of
112 KB may hold 6300x6300 pixels (119 MB once decoded, 45 s of CPU). So before any
pixel is decoded, ``open_compressed`` reads the header (Pillow reads only that
when it opens an image) and refuses an image that would decode to more than
``MAX_DECODE_PIXELS`` pixels. A JPEG is first drafted to the size its user wants
(libjpeg decodes it at 1/2, 1/4 or 1/8 scale at once), so the bound applies to
the pixels actually decoded. The decoding itself runs in an image thread
(``threads``), never on the event loop. One rule for every front end that
decodes such an image (D42; docs/limits.md, "Images the server decodes").
"""

from __future__ import annotations

import io
import warnings

from PIL import Image

from .images import ImageError

__all__ = ["DECODED_FORMATS", "MAX_DECODE_PIXELS", "open_compressed"]

#: Pixels of a compressed image decoded at most (a 3840x2160 frame, the video
#: server's ``MAX_PIXELS``); a larger one is refused from its header.
MAX_DECODE_PIXELS = 3840 * 2160
#: The formats decoded (Pillow's names); any other is refused unread.
DECODED_FORMATS = ("JPEG", "PNG")


def open_compressed(data: bytes, fit: int | None = None) -> Image.Image:
    """A JPEG or PNG image opened (header read, no pixel decoded) within the bound.

    Args:
        data: the image file's bytes (a ``CompressedImage``'s ``data``).
        fit: the longer side wanted, pixels: a JPEG is drafted to decode at the
            smallest scale still at least this large; None decodes it whole.

    Returns:
        The image, ready to decode (``load``, ``convert``...) in an image thread.

    Raises:
        ImageError: not a JPEG or PNG Pillow reads, or more than
            ``MAX_DECODE_PIXELS`` pixels to decode (``a 6300x6300 image is over
            8294400 pixels (MAX_DECODE_PIXELS)``).
    """
    try:
        with warnings.catch_warnings():  # the size is judged here, not by Pillow's warning
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            image = Image.open(io.BytesIO(data), formats=DECODED_FORMATS)
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as exc:
        raise ImageError(f"the compressed image cannot be read: {exc}") from None
    width, height = image.size
    if fit is not None:
        image.draft("RGB", (fit, fit))  # JPEG only; other formats keep their size
    if image.width * image.height > MAX_DECODE_PIXELS:
        image.close()
        decoded = (
            "" if image.size == (width, height) else f" (decoded {image.width}x{image.height})"
        )
        raise ImageError(
            f"a {width}x{height} image{decoded} is over {MAX_DECODE_PIXELS} pixels"
            " (MAX_DECODE_PIXELS)"
        )
    return image
