"""Table I of the Robot Web Tools paper: bandwidth of image streams (section IV.B).

The paper streamed a 640x480 USB camera at 30 Hz for 2 minutes and measured
MJPEG (quality 90), VP8 (bitrate 100 000) and the raw ROS image. Here a
synthetic camera plays the same size and rate (a textured scene panning past,
a moving object, sensor noise), 3600 frames (2 minutes) or 6 with ``--quick``,
and every row is measured on this run:

- raw ``sensor_msgs/Image`` over rosbridge as JSON (base64 data) and as CBOR;
- ``/stream?type=mjpeg&quality=90`` and ``/stream?type=vp8&bitrate=100000``
  from the video server's encoders, with their framing, at 30 frames a second;
- the encoders' CPU time per frame (this machine).

Usage: ``python -m benchmarks.paper.video [--quick]``.
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Iterator

import numpy as np
from PIL import Image

from rwt_graph.media import array_to_image
from rwt_video.params import StreamParams, StreamType

from ._streams import KB, RATE_HZ, mjpeg, paper_row, print_rows, rosbridge_bytes, stamp, video

_row = functools.partial(paper_row, "Table I")

#: Table I, KB/s: web MJPEG, web VP8, ROS raw, ROS compressed, ROS theora (means).
PAPER = {"mjpeg": 1317.0, "vp8": 342.2, "raw": 12052.5, "compressed": 1309.3, "theora": 19.4}
WIDTH, HEIGHT = 640, 480


def camera_frames(count: int, seed: int = 3) -> Iterator[np.ndarray]:
    """A 640x480 RGB sequence that compresses like a camera: texture, motion, noise."""
    rng = np.random.default_rng(seed)
    world_h, world_w = HEIGHT + 64, WIDTH + 4 * count // 3 + 64
    # smooth luminance at a few scales with a weak colour cast, plus hard-edged shapes
    world = np.zeros((world_h, world_w, 3), dtype=np.float32)
    for cell, weight in ((96, 70.0), (24, 30.0), (6, 10.0)):
        coarse = rng.uniform(-1, 1, (world_h // cell + 2, world_w // cell + 2))
        smooth = Image.fromarray(coarse.astype(np.float32), mode="F").resize(
            (coarse.shape[1] * cell, coarse.shape[0] * cell), Image.Resampling.BICUBIC
        )
        world += weight * np.asarray(smooth)[:world_h, :world_w, np.newaxis]
    world += 120 + rng.uniform(-12, 12, 3).astype(np.float32)
    for _ in range(world_w // 60):
        y, x = rng.integers(0, world_h - 60), rng.integers(0, world_w - 80)
        shade = rng.uniform(40, 220) + rng.uniform(-25, 25, 3)
        world[y : y + rng.integers(12, 60), x : x + rng.integers(12, 80)] = shade
    noise = rng.normal(0, 2.0, (4, HEIGHT, WIDTH, 3)).astype(np.float32)  # sensor noise
    for index in range(count):
        x0 = index * 4 // 3  # panning at 40 px/s
        frame = world[32 : 32 + HEIGHT, x0 : x0 + WIDTH].copy()
        cx = int(WIDTH / 2 + 200 * np.sin(index / 20))
        frame[200:280, max(cx - 40, 0) : cx + 40] = (220, 60, 40)  # a moving object
        frame += np.roll(noise[index % 4], index, axis=0)
        yield np.clip(frame, 0, 255).astype(np.uint8)


def messages(count: int) -> Iterator[dict[str, object]]:
    for index, pixels in enumerate(camera_frames(count)):
        yield array_to_image(pixels, "rgb8", header=stamp(index))


def run(quick: bool) -> list[dict[str, object]]:
    """Table I rows (see the module docstring)."""
    frames = 6 if quick else int(120 * RATE_HZ)
    note = f"{frames} frames 640x480 at 30 Hz, synthetic camera"
    first = next(messages(1))
    json_bytes, cbor_bytes = rosbridge_bytes("sensor_msgs/msg/Image", first)
    jpeg = mjpeg(messages(frames), StreamParams("/camera", StreamType.MJPEG, quality=90))
    vp8 = video(messages(frames), StreamParams("/camera", StreamType.VP8, bitrate=100_000))
    raw_note = "paper: ROS raw image; ours: rgb8 publish op"
    return [
        _row("raw Image over rosbridge, JSON", PAPER["raw"], json_bytes * RATE_HZ / KB, raw_note),
        _row("raw Image over rosbridge, CBOR", PAPER["raw"], cbor_bytes * RATE_HZ / KB, raw_note),
        _row("MJPEG quality 90 (/stream?type=mjpeg)", PAPER["mjpeg"], jpeg.kb_per_s, note),
        _row("VP8 100 kbit/s (/stream?type=vp8)", PAPER["vp8"], vp8.kb_per_s, note),
        _row("MJPEG encode CPU per frame", None, jpeg.cpu_ms_per_frame, "Pillow", "ms"),
        _row("VP8 encode CPU per frame", None, vp8.cpu_ms_per_frame, "libvpx realtime", "ms"),
    ]


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a few frames (CI smoke test)")
    print_rows(run(parser.parse_args().quick))
