"""The depth-cloud image codec (Robot Web Tools paper IV.C, depthcloud_encoder).

A depth image (metres) and an optional colour image become one square image of
four tiles, each ``tile_size`` pixels wide, which a browser receives as an
ordinary video stream and ros3djs's ``DepthCloud`` turns into points on the GPU::

    +--------------------+--------------------+
    | depth near 0..d    | depth far d..2d    |
    +--------------------+--------------------+
    | validity mask      | colour             |
    | (black = valid)    | (white if none)    |
    +--------------------+--------------------+

``d`` is ``max_depth_per_tile`` (depthcloud_encoder and ros3djs default to 1 m;
the paper split at 3 m). Each depth tile holds ``v = floor(depth' / d * 765)``
clamped to 0..765, where ``depth'`` is the depth (near tile) or depth minus d
(far tile), spread over the three channels as ``(min(v, 255), clamp(v - 255),
clamp(v - 510))`` so the channel sum is ``v``: ros3djs reads the sum, so the
channel order does not matter to it. Holes (NaN or zero) are filled by
interpolating along the row, which keeps the lossy codec from ringing at their
edges; the mask tells the decoder to drop those samples.

The source image is centred in its tile: cropped when larger than the tile,
padded with white (the mask then says "invalid") when smaller, as
depthcloud_encoder does. The output array is in the byte order of the
published ``bgr8`` image, so the bytes match depthcloud_encoder's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from .images import ImageError

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = [
    "DEPTH_LEVELS",
    "CameraIntrinsics",
    "DecodedDepthCloud",
    "decode_depthcloud",
    "encode_depthcloud",
    "fill_depth_holes",
    "points_from_depth",
    "tile_window",
]

U8Array = npt.NDArray[np.uint8]
F32Array = npt.NDArray[np.float32]
BoolArray = npt.NDArray[np.bool_]

#: Quantisation levels of one depth tile (three 8-bit channels summed).
DEPTH_LEVELS = 765


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of the depth camera, in pixels.

    Attributes:
        fx, fy: focal lengths.
        cx, cy: principal point.
    """

    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def from_camera_info(cls, msg: Mapping[str, object]) -> CameraIntrinsics:
        """From a ``sensor_msgs/CameraInfo`` (``k`` in ROS 2, ``K`` in ROS 1).

        Raises:
            ImageError: the message has no 9-element camera matrix.
        """
        k = msg.get("k", msg.get("K"))
        if not isinstance(k, list | tuple) or len(k) != 9:
            raise ImageError("CameraInfo has no 3x3 camera matrix k")
        return cls(float(k[0]), float(k[4]), float(k[2]), float(k[5]))

    @classmethod
    def centred(cls, width: int, height: int, focal_length: float = 525.0) -> CameraIntrinsics:
        """The image centre as principal point; 525 px is depthcloud_encoder's default ``f``."""
        return cls(focal_length, focal_length, width / 2, height / 2)


@dataclass(frozen=True)
class DecodedDepthCloud:
    """What ``decode_depthcloud`` rebuilds, in the source image's pixel grid.

    Attributes:
        depth: (height, width) float32 metres; NaN where the mask says invalid
            or the pixel lay outside the tile.
        colour: (height, width, 3) uint8 RGB.
        valid: (height, width) bool, True where ``depth`` is a sample.
    """

    depth: F32Array
    colour: U8Array
    valid: BoolArray


@dataclass(frozen=True)
class _Window:
    """Where the source image and its tile overlap: ``src[y0:y0+rows, x0:x0+cols]``."""

    src_y0: int
    src_x0: int
    dst_y0: int
    dst_x0: int
    rows: int
    cols: int


def tile_window(width: int, height: int, tile_size: int) -> _Window:
    """The part of a ``width`` x ``height`` source placed in a tile, centred on both."""

    def axis(size: int) -> tuple[int, int, int]:
        if size >= tile_size:
            return (size - tile_size) // 2, 0, tile_size
        return 0, (tile_size - size) // 2, size

    src_y0, dst_y0, rows = axis(height)
    src_x0, dst_x0, cols = axis(width)
    return _Window(src_y0, src_x0, dst_y0, dst_x0, rows, cols)


def fill_depth_holes(depth: F32Array) -> tuple[F32Array, BoolArray]:
    """Fill holes by linear interpolation along each row.

    A hole is a sample that is NaN, infinite or not positive (depthcloud_encoder
    counts NaN and 0). A hole between two samples takes the straight line
    between them; one at a row's end takes the nearest sample; a row without
    samples becomes 0. (depthcloud_encoder carries the last sample of the row
    above into a hole at a row's start; a row is filled on its own here.)

    Args:
        depth: (height, width) metres.

    Returns:
        (filled depth, valid) with ``valid`` True where ``depth`` held a sample.
    """
    width = depth.shape[1]
    valid = np.isfinite(depth) & (depth > 0)
    filled = np.where(valid, depth, np.float32(0)).astype(np.float32)
    rows, cols = np.nonzero(~valid)
    if rows.size == 0:
        return filled, valid
    columns = np.arange(width, dtype=np.int32)
    prev = np.maximum.accumulate(np.where(valid, columns, -1), axis=1)[rows, cols]
    flipped = np.where(valid, columns, width)[:, ::-1]
    nxt = np.minimum.accumulate(flipped, axis=1)[:, ::-1][rows, cols]
    has_left, has_right = prev >= 0, nxt < width
    left = filled[rows, np.maximum(prev, 0)]
    right = filled[rows, np.minimum(nxt, width - 1)]
    fraction = (cols - prev).astype(np.float32) / np.maximum(nxt - prev, 1).astype(np.float32)
    filled[rows, cols] = np.where(
        has_left & has_right,
        left + (right - left) * fraction,
        np.where(has_left, left, right),  # a row end; right is 0 in a row without samples
    )
    return filled, valid


def encode_depthcloud(
    depth: F32Array,
    colour: U8Array | None = None,
    *,
    max_depth_per_tile: float = 1.0,
    tile_size: int = 512,
) -> U8Array:
    """Encode one depth frame (and its colour) as the four-tile image.

    Args:
        depth: (height, width) metres; NaN or 0 where there is no sample.
        colour: (height, width, 3) uint8 RGB of the same size, or None (white).
        max_depth_per_tile: d in metres: the near tile spans 0..d, the far one d..2d;
            deeper samples saturate at 2d.
        tile_size: side of each tile in pixels; the image is twice that.

    Returns:
        (2 * tile_size, 2 * tile_size, 3) uint8 in the byte order of a ``bgr8``
        Image (see the module docstring).

    Raises:
        ImageError: ``colour`` does not match ``depth``, or a bad d or tile size.
    """
    if max_depth_per_tile <= 0 or tile_size <= 0:
        raise ImageError("max_depth_per_tile and tile_size must be positive")
    if colour is not None and colour.shape != (*depth.shape, 3):
        raise ImageError(f"colour {colour.shape} does not match depth {depth.shape}")
    filled, valid = fill_depth_holes(depth)
    near = _quantise(filled, max_depth_per_tile)
    far = _quantise(filled - np.float32(max_depth_per_tile), max_depth_per_tile)
    win = tile_window(depth.shape[1], depth.shape[0], tile_size)
    src = np.s_[win.src_y0 : win.src_y0 + win.rows, win.src_x0 : win.src_x0 + win.cols]
    out = np.full((2 * tile_size, 2 * tile_size, 3), 0xFF, dtype=np.uint8)

    def place(tile_y: int, tile_x: int, pixels: U8Array) -> None:
        y0, x0 = tile_y * tile_size + win.dst_y0, tile_x * tile_size + win.dst_x0
        out[y0 : y0 + win.rows, x0 : x0 + win.cols] = pixels[src]

    place(0, 0, _spread(near))
    place(0, 1, _spread(far))
    mask = np.where(valid, 0, 0xFF).astype(np.uint8)
    place(1, 0, np.repeat(mask[..., np.newaxis], 3, axis=2))
    if colour is not None:
        place(1, 1, colour[..., ::-1])  # RGB -> the bgr8 byte order
    return out


def decode_depthcloud(
    image: U8Array,
    *,
    width: int,
    height: int,
    max_depth_per_tile: float = 1.0,
    tolerance: int = 0,
) -> DecodedDepthCloud:
    """Rebuild depth and colour from a four-tile image (the inverse of ``encode_depthcloud``).

    A sample decodes from the far tile when the near tile is full (within
    ``tolerance`` of 765) and the far tile holds more than ``tolerance``; from
    the near tile otherwise; each at the middle of its quantisation step, so a
    lossless round trip is within ``max_depth_per_tile / 1530`` m. After a lossy
    codec, pass a tolerance of a few levels (ros3djs switches at 99 % of the
    near range). The mask tile marks a sample invalid above mid-grey, as
    ros3djs's shader does.

    Args:
        image: (2T, 2T, 3) uint8 in the published ``bgr8`` byte order.
        width: width of the source depth image, pixels.
        height: height of the source depth image, pixels.
        max_depth_per_tile: the d used to encode.
        tolerance: codec noise to allow, in levels of 765.

    Returns:
        The depth (NaN where invalid), colour and validity in the source grid.

    Raises:
        ImageError: ``image`` is not a (2T, 2T, 3) array.
    """
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] != image.shape[1]:
        raise ImageError(f"a depth-cloud image is (2T, 2T, 3), not {image.shape}")
    tile = image.shape[0] // 2
    win = tile_window(width, height, tile)

    def take(tile_y: int, tile_x: int) -> npt.NDArray[np.int32]:
        y0, x0 = tile_y * tile + win.dst_y0, tile_x * tile + win.dst_x0
        return image[y0 : y0 + win.rows, x0 : x0 + win.cols].astype(np.int32)

    near, far = take(0, 0).sum(axis=2), take(0, 1).sum(axis=2)
    step = np.float32(max_depth_per_tile / DEPTH_LEVELS)
    use_far = (near >= DEPTH_LEVELS - tolerance) & (far > tolerance)
    metres = np.where(
        use_far,
        np.float32(max_depth_per_tile) + (far + np.float32(0.5)) * step,
        (np.minimum(near, DEPTH_LEVELS) + np.float32(0.5)) * step,
    )
    inside = take(1, 0).mean(axis=2) <= 127
    depth = np.full((height, width), np.nan, dtype=np.float32)
    colour = np.zeros((height, width, 3), dtype=np.uint8)
    valid = np.zeros((height, width), dtype=bool)
    dst = np.s_[win.src_y0 : win.src_y0 + win.rows, win.src_x0 : win.src_x0 + win.cols]
    depth[dst] = np.where(inside, metres, np.nan)
    colour[dst] = take(1, 1)[..., ::-1].astype(np.uint8)
    valid[dst] = inside
    return DecodedDepthCloud(depth, colour, valid)


def points_from_depth(
    depth: F32Array,
    intrinsics: CameraIntrinsics,
    colour: U8Array | None = None,
) -> tuple[F32Array, U8Array | None]:
    """Back-project valid depth samples through a pinhole camera.

    Args:
        depth: (height, width) metres, NaN where there is no sample.
        intrinsics: of the depth camera, in the same pixel grid.
        colour: (height, width, 3) RGB to pick per point, or None.

    Returns:
        ((N, 3) float32 x, y, z in metres in the optical frame (x right, y down,
        z forward), (N, 3) uint8 colours or None), N the number of samples.
    """
    v, u = np.nonzero(np.isfinite(depth))
    z = depth[v, u]
    x = (u - intrinsics.cx) * z / intrinsics.fx
    y = (v - intrinsics.cy) * z / intrinsics.fy
    points = np.stack([x, y, z], axis=1).astype(np.float32)
    return points, (colour[v, u] if colour is not None else None)


def _quantise(metres: F32Array, max_depth_per_tile: float) -> npt.NDArray[np.int32]:
    """Depth to 0..765 by truncation, as depthcloud_encoder (float maths, then int)."""
    scaled = metres / np.float32(max_depth_per_tile) * np.float32(DEPTH_LEVELS)
    scaled = np.nan_to_num(scaled, nan=0.0)
    levels: npt.NDArray[np.int32] = np.clip(scaled, 0, DEPTH_LEVELS).astype(np.int32)
    return levels


def _spread(levels: npt.NDArray[np.int32]) -> U8Array:
    """0..765 over three channels whose sum is the level (depthcloud_encoder's split)."""
    parts = [np.clip(levels - offset, 0, 255) for offset in (0, 255, 510)]
    return np.stack(parts, axis=-1).astype(np.uint8)
