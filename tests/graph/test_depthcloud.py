"""The depth-cloud codec (paper IV.C, depthcloud_encoder layout) and its graph node."""

from __future__ import annotations

import numpy as np
import pytest

from rwt_graph.graph import Graph
from rwt_graph.media import (
    CameraIntrinsics,
    array_to_image,
    decode_depthcloud,
    encode_depthcloud,
    fill_depth_holes,
    image_to_array,
    points_from_depth,
)
from rwt_graph.media.depthcloud_node import DepthCloudEncoder

NAN = np.nan
W = 255  # white: padding, "invalid" in the mask, no colour


def known_depth() -> np.ndarray:
    # 2 rows x 6 columns; with tile 4 the middle 4 columns are kept and the
    # 2 rows are centred (tile rows 1 and 2). Holes: NaN at (0, 2), 0 at (1, 1).
    return np.array(
        [
            [9.0, 0.5, NAN, 1.5, 3.0, 9.0],
            [9.0, 0.0, 2.0, 4.5, 0.25, 9.0],
        ],
        dtype=np.float32,
    )


def expected_tiles(with_colour: bool) -> np.ndarray:
    # d = 2 m: level = floor(depth / 2 * 765), channels (min(v,255), v-255, v-510) clamped.
    # (0,2) is filled with 1.0 (between 0.5 and 1.5); (1,1) with 5.5 (between 9.0 and 2.0).
    near = [
        [(191, 0, 0), (255, 127, 0), (255, 255, 63), (255, 255, 255)],  # 0.5 1.0 1.5 3.0
        [(255, 255, 255), (255, 255, 255), (255, 255, 255), (95, 0, 0)],  # 5.5 2.0 4.5 0.25
    ]
    far = [
        [(0, 0, 0), (0, 0, 0), (0, 0, 0), (255, 127, 0)],  # 3.0 - 2 = 1.0 -> 382
        [(255, 255, 255), (0, 0, 0), (255, 255, 255), (0, 0, 0)],  # 3.5, 0, 2.5 saturate
    ]
    mask = [[0, W, 0, 0], [W, 0, 0, 0]]
    out = np.full((8, 8, 3), W, dtype=np.uint8)
    for row in range(2):
        for col in range(4):
            out[1 + row, col] = near[row][col]
            out[1 + row, 4 + col] = far[row][col]
            out[5 + row, col] = (mask[row][col],) * 3
            if with_colour:
                source_col = col + 1
                out[5 + row, 4 + col] = (200, 100 + row, 10 * source_col)  # BGR
    return out


def known_colour() -> np.ndarray:
    colour = np.zeros((2, 6, 3), dtype=np.uint8)
    for row in range(2):
        for col in range(6):
            colour[row, col] = (10 * col, 100 + row, 200)  # RGB
    return colour


@pytest.mark.parametrize("with_colour", [False, True])
def test_tile_layout_pixel_by_pixel(with_colour: bool) -> None:
    colour = known_colour() if with_colour else None
    tiles = encode_depthcloud(known_depth(), colour, max_depth_per_tile=2.0, tile_size=4)
    np.testing.assert_array_equal(tiles, expected_tiles(with_colour))


def test_default_size_is_1024_square() -> None:
    depth = np.ones((480, 640), dtype=np.float32)
    tiles = encode_depthcloud(depth)
    assert tiles.shape == (1024, 1024, 3)
    # 640x480 in a 512 tile: columns 64..575 kept, rows padded 16 above and below
    assert (tiles[16:496, :512] == (255, 255, 255)).all()  # 1 m = d: full near tile
    assert (tiles[:16, 512:] == 255).all() and (tiles[16:496, 512:1024] == 0).all()
    assert (tiles[512 + 16 : 512 + 496, :512] == 0).all()  # all valid
    assert (tiles[512 : 512 + 16, :512] == 255).all()  # padding is invalid


def test_holes_are_interpolated_along_rows() -> None:
    depth = np.array(
        [[NAN, 1.0, NAN, NAN, 4.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]], dtype=np.float32
    )
    filled, valid = fill_depth_holes(depth)
    np.testing.assert_allclose(filled, [[1, 1, 2, 3, 4, 4], [0, 0, 0, 0, 0, 0]])
    assert valid.tolist() == [[False, True, False, False, True, False], [False] * 6]


def random_frame(seed: int, shape: tuple[int, int] = (120, 160)) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    depth = rng.uniform(0.05, 1.95, shape).astype(np.float32)
    depth[rng.random(shape) < 0.15] = NAN
    depth[rng.random(shape) < 0.05] = 0.0
    colour = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)
    return depth, colour


def test_round_trip_within_the_quantisation_error() -> None:
    depth, colour = random_frame(1)
    tiles = encode_depthcloud(depth, colour, max_depth_per_tile=1.0, tile_size=128)
    decoded = decode_depthcloud(tiles, width=160, height=120, max_depth_per_tile=1.0)
    kept = np.s_[:, 16:144]  # 160 columns centred in a 128 tile
    expected_valid = np.isfinite(depth) & (depth > 0)
    assert (decoded.valid[kept] == expected_valid[kept]).all()
    assert not decoded.valid[:, :16].any() and np.isnan(decoded.depth[:, :16]).all()
    error = np.abs(decoded.depth - depth)[decoded.valid]
    assert error.max() <= 1.0 / 1530 + 1e-6  # half a step of d / 765
    assert (decoded.colour[kept] == colour[kept]).all()


def test_points_from_depth_back_project_through_the_pinhole() -> None:
    depth = np.full((4, 6), 2.0, dtype=np.float32)
    depth[0, 0] = NAN
    colour = np.zeros((4, 6, 3), dtype=np.uint8)
    colour[3, 5] = (1, 2, 3)
    intrinsics = CameraIntrinsics.from_camera_info({"k": [4.0, 0, 3.0, 0, 2.0, 2.0, 0, 0, 1]})
    points, colours = points_from_depth(depth, intrinsics, colour)
    assert points.shape == (23, 3) and colours is not None
    last = points[-1]  # pixel (u=5, v=3)
    np.testing.assert_allclose(last, [(5 - 3.0) * 2 / 4.0, (3 - 2.0) * 2 / 2.0, 2.0])
    assert colours[-1].tolist() == [1, 2, 3]


def stamped(msg: dict[str, object], sec: int) -> dict[str, object]:
    return msg | {"header": {"stamp": {"sec": sec, "nanosec": 0}, "frame_id": "camera"}}


def test_encoder_node_publishes_the_encoded_frame_with_matching_colour() -> None:
    graph = Graph()
    DepthCloudEncoder(graph, "/cam/depth", "/cam/rgb", max_depth_per_tile=1.0, tile_size=128)
    got: list[dict[str, object]] = []
    graph.create_subscription("/depthcloud_encoded", got.append)
    depth_pub = graph.create_publisher("/cam/depth", "sensor_msgs/msg/Image")
    rgb_pub = graph.create_publisher("/cam/rgb", "sensor_msgs/msg/Image")
    depth, colour = random_frame(2)
    millimetres = np.nan_to_num(depth * 1000).round().astype(np.uint16)
    other = np.zeros_like(colour)

    rgb_pub.publish(stamped(array_to_image(other, "rgb8"), 1))
    depth_pub.publish(stamped(array_to_image(millimetres, "16UC1"), 2))
    assert got == []  # waits for the colour frame of its stamp
    rgb_pub.publish(stamped(array_to_image(colour, "rgb8"), 2))
    [msg] = got
    assert msg["encoding"] == "bgr8" and (msg["width"], msg["height"]) == (256, 256)
    assert msg["header"]["stamp"] == {"sec": 2, "nanosec": 0}  # type: ignore[index]
    decoded = decode_depthcloud(image_to_array(msg), width=160, height=120)
    kept = np.s_[:, 16:144]
    assert (decoded.colour[kept] == colour[kept]).all()
    error = np.abs(decoded.depth - millimetres / 1000.0)[decoded.valid]
    assert error.max() <= 1.0 / 1530 + 1e-6

    # colour first, then depth of the same stamp: out at once
    rgb_pub.publish(stamped(array_to_image(other, "rgb8"), 3))
    depth_pub.publish(stamped(array_to_image(millimetres, "16UC1"), 3))
    assert len(got) == 2


def test_encoder_node_without_colour_and_with_bad_input() -> None:
    graph = Graph()
    encoder = DepthCloudEncoder(graph, "/depth", tile_size=64)
    got: list[dict[str, object]] = []
    graph.create_subscription("/depthcloud_encoded", got.append)
    depth_pub = graph.create_publisher("/depth", "sensor_msgs/msg/Image")
    depth_pub.publish(array_to_image(np.zeros((8, 8, 3), dtype=np.uint8), "rgb8"))  # not depth
    assert got == []
    depth_pub.publish(array_to_image(np.full((8, 8), 0.5, dtype=np.float32), "32FC1"))
    [msg] = got
    tiles = image_to_array(msg)
    assert (tiles[28:36, 28:36] == (255, 127, 0)).all()  # 0.5 m of d = 1 m: level 382
    assert (tiles[64:, 64:] == 255).all()
    encoder.close()
    depth_pub.publish(array_to_image(np.full((8, 8), 0.5, dtype=np.float32), "32FC1"))
    assert len(got) == 1
