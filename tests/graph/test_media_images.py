"""sensor_msgs/Image to displayable RGB, as web_video_server converts it."""

from __future__ import annotations

import numpy as np
import pytest

from rwt_graph.media import (
    ImageError,
    array_to_image,
    compressed_content_type,
    depth_to_metres,
    image_to_array,
    image_to_display,
)


def image(encoding: str, data: bytes, width: int, height: int, step: int, **extra: object) -> dict:
    return {
        "encoding": encoding,
        "width": width,
        "height": height,
        "step": step,
        "data": data,
        "is_bigendian": 0,
    } | extra


def test_colour_encodings_become_rgb() -> None:
    rgb = image("rgb8", bytes([1, 2, 3, 4, 5, 6]), 2, 1, 6)
    bgr = image("bgr8", bytes([3, 2, 1, 6, 5, 4]), 2, 1, 6)
    bgra = image("bgra8", bytes([3, 2, 1, 9, 6, 5, 4, 8]), 2, 1, 8)
    for msg in (rgb, bgr, bgra):
        assert image_to_display(msg).tolist() == [[[1, 2, 3], [4, 5, 6]]]
    assert image_to_display(bgra, keep_alpha=True).tolist() == [[[1, 2, 3, 9], [4, 5, 6, 8]]]


def test_rows_with_padding_and_big_endian_samples() -> None:
    padded = image("mono8", bytes([7, 8, 0, 0, 9, 10, 0, 0]), 2, 2, 4)
    assert image_to_array(padded).tolist() == [[7, 8], [9, 10]]
    big = image("16UC1", (1000).to_bytes(2, "big") + (2500).to_bytes(2, "big"), 2, 1, 4)
    big["is_bigendian"] = 1
    assert depth_to_metres(big).tolist() == [[1.0, 2.5]]


def test_mono16_scales_to_8_bits_and_depth_scales_its_maximum_to_255() -> None:
    mono16 = array_to_image(np.array([[0, 65535, 32896]], dtype=np.uint16), "mono16")
    assert image_to_display(mono16)[..., 0].tolist() == [[0, 255, 128]]
    depth = np.array([[np.nan, 0.5, 2.0, -1.0]], dtype=np.float32)
    shown = image_to_display(array_to_image(depth, "32FC1"))
    assert shown[..., 0].tolist() == [[0, 63, 255, 0]] and shown.shape == (1, 4, 3)
    millimetres = array_to_image(np.array([[0, 1000, 4000]], dtype=np.uint16), "16UC1")
    assert image_to_display(millimetres)[..., 1].tolist() == [[0, 63, 255]]


@pytest.mark.parametrize(
    ("msg", "text"),
    [
        (image("yuv422", b"\0" * 4, 1, 1, 4), "unsupported image encoding"),
        (image("rgb8", b"\0" * 5, 2, 1, 6), "do not hold"),
        (image("rgb8", b"\0" * 6, 2, 1, 3), "do not hold"),
        (image("rgb8", b"", 0, 0, 0), "empty image"),
    ],
)
def test_bad_images_raise_image_error(msg: dict, text: str) -> None:
    with pytest.raises(ImageError, match=text):
        image_to_display(msg)


def test_only_depth_encodings_are_depth() -> None:
    with pytest.raises(ImageError, match="32FC1"):
        depth_to_metres(image("rgb8", b"\0" * 3, 1, 1, 3))


def test_compressed_formats() -> None:
    assert compressed_content_type("rgb8; jpeg compressed bgr8") == "image/jpeg"
    assert compressed_content_type("png") == "image/png"
    assert compressed_content_type("theora") is None
