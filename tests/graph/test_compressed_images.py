"""Compressed images decoded within MAX_DECODE_PIXELS, judged from their header (D42)."""

from __future__ import annotations

import io

import pytest
from PIL import Image

from rwt_graph.media.compressed import MAX_DECODE_PIXELS, open_compressed
from rwt_graph.media.images import ImageError


def _encoded(size: tuple[int, int], image_format: str) -> bytes:
    out = io.BytesIO()
    Image.new("RGB", size, (10, 20, 30)).save(out, image_format)
    return out.getvalue()


@pytest.mark.parametrize("image_format", ["PNG", "JPEG"])
def test_an_image_within_the_bound_opens_and_decodes(image_format: str) -> None:
    image = open_compressed(_encoded((64, 48), image_format))
    assert image.size == (64, 48)
    assert image.convert("RGB").getpixel((0, 0))[0] in range(5, 16)


def test_a_large_jpeg_is_drafted_to_the_size_wanted() -> None:
    image = open_compressed(_encoded((800, 600), "JPEG"), fit=100)
    assert image.size[0] < 800 and image.size[0] >= 100


def test_an_image_over_the_bound_is_refused_from_its_header() -> None:
    side = int(MAX_DECODE_PIXELS**0.5) + 100
    data = _encoded((side, side), "PNG")  # small on the wire: one colour
    with pytest.raises(ImageError, match=rf"a {side}x{side} image is over {MAX_DECODE_PIXELS}"):
        open_compressed(data)


@pytest.mark.parametrize("data", [b"", b"not an image", _encoded((4, 4), "GIF")])
def test_what_is_not_a_jpeg_or_png_is_refused_unread(data: bytes) -> None:
    with pytest.raises(ImageError, match="cannot be read"):
        open_compressed(data)
