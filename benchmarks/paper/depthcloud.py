"""Table II of the Robot Web Tools paper: point cloud streaming (section IV.C).

The paper streamed an ASUS Xtion's RGBD data for 2 minutes: 5591.6 KB/s as ROS
point clouds against 568.4 KB/s as the depth-cloud image over VP8 (90 % less).
Here a synthetic 640x480 RGBD camera at 30 Hz (a room: back wall, floor, a
sphere moving through it; sensor holes at edges and scattered dropouts) plays
300 frames (3 with ``--quick``), and every row is measured on this run:

- the organised ``sensor_msgs/PointCloud2`` (x, y, z, rgb as float32, 16 bytes a
  point) over rosbridge as JSON and CBOR;
- the depth-cloud image (``DepthCloudEncoder``: 1024x1024, depth split at the
  paper's 3 m) through the video server's VP8 (default 100 kbit/s, as the paper
  kept the defaults, and 1 Mbit/s) and MJPEG (quality 90) encoders;
- after each lossy codec, the depth a Python client rebuilds from what it
  decoded (``decode_depthcloud``): median error in mm over the samples that
  stay valid, and the share of samples kept;
- the depth-cloud encoding's CPU time per frame.

Usage: ``python -m benchmarks.paper.depthcloud [--quick]``.
"""

from __future__ import annotations

import argparse
import functools
import statistics
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from rwt_graph.graph import Graph
from rwt_graph.media import CameraIntrinsics, array_to_image, decode_depthcloud
from rwt_graph.media.depthcloud_node import DepthCloudEncoder
from rwt_video.params import StreamParams, StreamType

from ._streams import (
    KB,
    RATE_HZ,
    StreamResult,
    mjpeg,
    paper_row,
    print_rows,
    rosbridge_bytes,
    stamp,
    video,
)

_row = functools.partial(paper_row, "Table II")

#: Table II, KB/s: ROS internal (point cloud) and web streaming (means).
PAPER = {"pointcloud": 5591.6, "web": 568.4}
WIDTH, HEIGHT = 640, 480
CAMERA = CameraIntrinsics.centred(WIDTH, HEIGHT)  # f = 525 px, as depthcloud_encoder
SPLIT_M = 3.0  # the paper's max depth per tile
TOLERANCE = 8  # codec noise allowed when choosing the far tile, levels of 765


def rgbd_frames(count: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(depth in metres with NaN holes, RGB) of a room with a moving sphere."""
    rng = np.random.default_rng(5)
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float32)
    rays = np.stack([(u - CAMERA.cx) / CAMERA.fx, (v - CAMERA.cy) / CAMERA.fy], axis=-1)
    wall = np.full((HEIGHT, WIDTH), 3.5, dtype=np.float32)
    below = rays[..., 1] > 1e-3
    floor = np.where(below, 1.0 / np.maximum(rays[..., 1], 1e-3), np.inf)  # camera 1 m up
    room = np.minimum(wall, floor).astype(np.float32)
    texture = 150 + 40 * np.sin(u / 23.0)[..., np.newaxis] * np.array([1.0, 0.8, 0.6])
    checker = ((np.floor(u / 40) + np.floor(v / 40)) % 2)[..., np.newaxis] * 60 + 80
    room_rgb = np.where((floor < wall)[..., np.newaxis], checker, texture).astype(np.float32)
    dropouts = rng.random((8, HEIGHT, WIDTH)) < 0.02
    for index in range(count):
        depth, rgb = room.copy(), room_rgb.copy()
        centre = np.array([0.6 * np.sin(index / 15), 0.1, 1.6], dtype=np.float32)
        hit, t = _sphere(rays, centre, 0.35)
        closer = hit & (t < depth)
        depth[closer] = t[closer]
        rgb[closer] = (200, 50, 40)
        depth[:, :8] = np.nan  # the projector's shadow band
        depth[dropouts[index % 8]] = np.nan
        yield depth, np.clip(rgb, 0, 255).astype(np.uint8)


def _sphere(rays: np.ndarray, centre: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Where rays (x/z, y/z) hit a sphere, and the depth z of the hit."""
    d = np.concatenate([rays, np.ones((*rays.shape[:2], 1), dtype=np.float32)], axis=-1)
    a = (d * d).sum(-1)
    b = -2 * (d * centre).sum(-1)
    c = float(centre @ centre) - radius * radius
    disc = b * b - 4 * a * c
    hit = disc >= 0
    t = (-b - np.sqrt(np.where(hit, disc, 0))) / (2 * a)
    return hit, t.astype(np.float32)


def point_cloud(depth: np.ndarray, rgb: np.ndarray) -> dict[str, object]:
    """An organised PointCloud2 (x, y, z, rgb float32; NaN where no sample)."""
    x = (np.arange(WIDTH) - CAMERA.cx) / CAMERA.fx * depth
    y = (np.arange(HEIGHT)[:, np.newaxis] - CAMERA.cy) / CAMERA.fy * depth
    packed = (
        (rgb[..., 0].astype(np.uint32) << 16)
        | (rgb[..., 1].astype(np.uint32) << 8)
        | rgb[..., 2].astype(np.uint32)
    )
    points = np.stack([x, y, depth, packed.view(np.float32)], axis=-1).astype(np.float32)
    fields = [
        {"name": name, "offset": 4 * i, "datatype": 7, "count": 1}
        for i, name in enumerate(("x", "y", "z", "rgb"))
    ]
    return {
        "header": stamp(0),
        "height": HEIGHT,
        "width": WIDTH,
        "fields": fields,
        "is_bigendian": False,
        "point_step": 16,
        "row_step": 16 * WIDTH,
        "data": points.tobytes(),
        "is_dense": False,
    }


@dataclass
class Encoded:
    """The depth-cloud image messages of a sequence and the encoder's CPU time."""

    count: int
    cpu_s: float = 0.0
    truth: dict[int, np.ndarray] = field(default_factory=dict)

    def messages(self) -> Iterator[dict[str, object]]:
        encoder = DepthCloudEncoder(Graph(), "/depth", max_depth_per_tile=SPLIT_M)
        for index, (depth, rgb) in enumerate(rgbd_frames(self.count)):
            started = time.process_time()
            msg = encoder.encode(
                array_to_image(depth, "32FC1", header=stamp(index)), array_to_image(rgb, "rgb8")
            )
            self.cpu_s += time.process_time() - started
            self.truth[index] = depth
            yield msg


class DepthError:
    """Collects the rebuilt depth's error per decoded frame."""

    def __init__(self, truth: dict[int, np.ndarray]) -> None:
        self.truth = truth
        self.medians_mm: list[float] = []
        self.kept: list[float] = []

    def __call__(self, index: int, shown: np.ndarray) -> None:
        depth = self.truth.pop(index, None)
        if depth is None:
            return
        decoded = decode_depthcloud(
            shown[..., ::-1].copy(),  # shown as RGB; the message's bytes are BGR order
            width=WIDTH,
            height=HEIGHT,
            max_depth_per_tile=SPLIT_M,
            tolerance=TOLERANCE,
        )
        inside = np.zeros_like(decoded.valid)
        inside[:, 64:576] = True  # the columns a 512 tile keeps
        expected = np.isfinite(depth) & inside
        both = decoded.valid & expected
        self.medians_mm.append(float(np.median(np.abs(decoded.depth - depth)[both])) * 1000)
        self.kept.append(both.sum() / max(expected.sum(), 1))


def run(quick: bool) -> list[dict[str, object]]:
    """Table II rows (see the module docstring)."""
    frames = 3 if quick else 300
    depth, rgb = next(rgbd_frames(1))
    json_bytes, cbor_bytes = rosbridge_bytes("sensor_msgs/msg/PointCloud2", point_cloud(depth, rgb))
    cloud_note = "paper: ROS point cloud; ours: 640x480 organised, 16 B/point"
    rows = [
        _row(
            "PointCloud2 over rosbridge, JSON",
            PAPER["pointcloud"],
            json_bytes * RATE_HZ / KB,
            cloud_note,
        ),
        _row(
            "PointCloud2 over rosbridge, CBOR",
            PAPER["pointcloud"],
            cbor_bytes * RATE_HZ / KB,
            cloud_note,
        ),
    ]
    codecs = [
        ("VP8 100 kbit/s", StreamParams("/depthcloud_encoded", StreamType.VP8), PAPER["web"]),
        (
            "VP8 1 Mbit/s",
            StreamParams("/depthcloud_encoded", StreamType.VP8, bitrate=1_000_000),
            None,
        ),
        ("MJPEG quality 90", StreamParams("/depthcloud_encoded", quality=90), None),
    ]
    encode_cpu = 0.0
    for name, params, paper in codecs:
        encoded = Encoded(frames)
        errors = DepthError(encoded.truth)
        stream = (video if params.type.is_video else mjpeg)(encoded.messages(), params, errors)
        encode_cpu = encoded.cpu_s / frames * 1000
        rows += _codec_rows(name, paper, stream, errors, cbor_bytes, frames)
    rows.append(_row("depth-cloud encode CPU per frame", None, encode_cpu, "numpy", "ms"))
    return rows


def _codec_rows(
    name: str, paper: float | None, stream: StreamResult, errors: DepthError, cloud: int, n: int
) -> list[dict[str, object]]:
    saved = 100 * (1 - stream.kb_per_s / (cloud * RATE_HZ / KB))
    note = f"{n} frames, {saved:.1f} % less than PointCloud2 CBOR"
    kept = 100 * statistics.mean(errors.kept) if errors.kept else 0.0
    median = statistics.median(errors.medians_mm) if errors.medians_mm else float("nan")
    return [
        _row(f"depth cloud as {name}", paper, stream.kb_per_s, note),
        _row(
            f"depth cloud as {name}: median depth error",
            None,
            median,
            f"{kept:.1f} % of samples kept",
            "mm",
        ),
    ]


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a few frames (CI smoke test)")
    print_rows(run(parser.parse_args().quick))
