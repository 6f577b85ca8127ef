"""PNG compression (spec 3.1.2, D20, REF §3.3, paper section IV.D)."""

from __future__ import annotations

import base64
import io
import struct
import zlib

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st
from PIL import Image

from rwt_protocol.codecs.png import decode_png, encode_png, png_dimensions
from rwt_protocol.errors import RemoteProtocolError

MiB = 1024 * 1024

json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(), inner, max_size=5),
    max_leaves=30,
)


@given(value=json_values)
def test_png_round_trip_of_any_json(value: object) -> None:
    text = msgspec.json.encode({"op": "publish", "topic": "/t", "msg": value})
    assert decode_png(encode_png(text), max_bytes=MiB) == text
    assert msgspec.json.decode(decode_png(encode_png(text), max_bytes=MiB)) == {
        "op": "publish",
        "topic": "/t",
        "msg": value,
    }


def _image(data: str) -> Image.Image:
    return Image.open(io.BytesIO(base64.b64decode(data, validate=True)))


def test_layout_is_the_reference_one() -> None:
    # REF §3.3: L = 100 -> width 5, height 7, 105 bytes, 5 padding newlines.
    text = b"x" * 100
    assert png_dimensions(100) == (5, 7)
    image = _image(encode_png(text))
    assert image.format == "PNG" and image.mode == "RGB" and image.size == (5, 7)
    assert image.tobytes() == text + b"\n" * 5


@pytest.mark.parametrize(
    ("length", "size"), [(1, (1, 1)), (2, (1, 1)), (3, (1, 1)), (12, (2, 2)), (13, (2, 3))]
)
def test_small_inputs_get_a_valid_image(length: int, size: tuple[int, int]) -> None:
    assert png_dimensions(length) == size
    text = b"7" * length
    assert decode_png(encode_png(text), max_bytes=MiB) == text


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def _filtered_row(kind: int, row: bytes, prior: bytes, bpp: int) -> bytes:
    """Apply PNG filter ``kind`` (0 None, 1 Sub, 2 Up, 3 Average, 4 Paeth) to one row."""
    out = bytearray()
    for i, x in enumerate(row):
        a = row[i - bpp] if i >= bpp else 0
        b = prior[i]
        c = prior[i - bpp] if i >= bpp else 0
        if kind == 0:
            predicted = 0
        elif kind == 1:
            predicted = a
        elif kind == 2:
            predicted = b
        elif kind == 3:
            predicted = (a + b) // 2
        else:
            p = a + b - c
            pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            predicted = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
        out.append((x - predicted) & 0xFF)
    return bytes([kind]) + bytes(out)


def _png(pixels: bytes, width: int, height: int, filters: list[int], color: int = 2) -> str:
    """A PNG written by hand, row ``i`` filtered with ``filters[i % len(filters)]``."""
    bpp = {0: 1, 2: 3, 6: 4}[color]
    stride = width * bpp
    rows, prior = [], bytes(stride)
    for y in range(height):
        row = pixels[y * stride : (y + 1) * stride]
        rows.append(_filtered_row(filters[y % len(filters)], row, prior, bpp))
        prior = row
    header = struct.pack(">IIBBBBB", width, height, 8, color, 0, 0, 0)
    body = _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(b"".join(rows)))
    return base64.b64encode(b"\x89PNG\r\n\x1a\n" + body + _chunk(b"IEND", b"")).decode()


@pytest.mark.parametrize("kind", [0, 1, 2, 3, 4])
def test_every_png_filter_type_decodes(kind: int) -> None:
    text = b'{"op":"publish","topic":"/chatter","msg":{"data":"filters 0-4, all of them"}}'
    width, height = png_dimensions(len(text))
    padded = text + b"\n" * (width * height * 3 - len(text))
    assert decode_png(_png(padded, width, height, [kind]), max_bytes=MiB) == text


def test_mixed_filters_grayscale_rgba_and_nul_padding_decode() -> None:
    text = b'{"op":"set_level","level":"info"}'
    gray = text + b"\x00" * (6 * 6 - len(text))
    assert decode_png(_png(gray, 6, 6, [0, 1, 2, 3, 4], color=0), max_bytes=MiB) == text
    rgba = text + b"\n" * (3 * 3 * 4 - len(text))
    assert decode_png(_png(rgba, 3, 3, [4, 3], color=6), max_bytes=MiB) == text


def test_bad_data_is_refused() -> None:
    with pytest.raises(RemoteProtocolError, match="not valid base64"):
        decode_png("not base64!", max_bytes=MiB)
    with pytest.raises(RemoteProtocolError, match="not valid base64"):
        decode_png("\x80", max_bytes=MiB)  # not ASCII (found by hypothesis)
    with pytest.raises(RemoteProtocolError, match="not a valid PNG"):
        decode_png(base64.b64encode(b"GIF89a....").decode(), max_bytes=MiB)
    truncated = base64.b64decode(encode_png(b"x" * 3000))[:-30]
    with pytest.raises(RemoteProtocolError, match="not a valid PNG"):
        decode_png(base64.b64encode(truncated).decode(), max_bytes=MiB)
    out = io.BytesIO()
    Image.new("P", (4, 4)).save(out, format="PNG")
    with pytest.raises(RemoteProtocolError, match="got mode P"):
        decode_png(base64.b64encode(out.getvalue()).decode(), max_bytes=MiB)


def test_size_is_checked_before_inflating() -> None:
    # 2000x2000 RGB of zeros: a few KB of PNG, 12 MB of pixels.
    out = io.BytesIO()
    Image.new("RGB", (2000, 2000)).save(out, format="PNG")
    assert len(out.getvalue()) < 100_000
    with pytest.raises(RemoteProtocolError, match="2000x2000 RGB holds more than"):
        decode_png(base64.b64encode(out.getvalue()).decode(), max_bytes=10 * MiB)
    huge = struct.pack(">IIBBBBB", 100_000, 100_000, 8, 2, 0, 0, 0)
    bomb = b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", huge) + _chunk(b"IEND", b"")
    with pytest.raises(RemoteProtocolError, match="holds more than"):
        decode_png(base64.b64encode(bomb).decode(), max_bytes=10 * MiB)
