"""Depth clouds for ros3djs and the camera geometry behind them (docs/video.md).

These load numpy and Pillow with their first use (the ``server`` extra).

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_graph.media import (
        CameraIntrinsics,
        DecodedDepthCloud,
        ImageError,
        decode_depthcloud,
        encode_depthcloud,
        points_from_depth,
    )
    from rwt_graph.media.depthcloud_node import DepthCloudEncoder

__all__ = [
    "CameraIntrinsics",
    "DecodedDepthCloud",
    "DepthCloudEncoder",
    "ImageError",
    "decode_depthcloud",
    "encode_depthcloud",
    "points_from_depth",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
