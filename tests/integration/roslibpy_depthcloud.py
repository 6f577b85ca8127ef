"""Publish a depth and a colour frame through roslibpy and receive the encoded depth cloud.

Usage: python roslibpy_depthcloud.py HOST PORT FRAMES.npz OUT.bin

The real roslibpy client publishes the ``depth`` (32FC1) and ``rgb`` (rgb8) arrays
of FRAMES.npz on ``/camera/depth`` and ``/camera/rgb`` with one stamp per pair,
ten pairs a second, and subscribes to ``/depthcloud_encoded`` as ros3djs users
do. It writes the first encoded image's pixels to OUT.bin, prints its fields as
JSON, and goes on publishing until its standard input closes (the test reads
the video stream meanwhile) or 30 s pass. Runs in its own process because
twisted's reactor starts once per process.
"""

from __future__ import annotations

import base64
import json
import sys
import threading
import time

import numpy as np
import roslibpy

LIMIT_S = 30.0


def image(pixels: np.ndarray, encoding: str, sec: int) -> dict[str, object]:
    height, width = pixels.shape[:2]
    return {
        "header": {"stamp": {"sec": sec, "nanosec": 0}, "frame_id": "camera"},
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": pixels.strides[0],
        "data": base64.b64encode(pixels.tobytes()).decode(),
    }


def main() -> int:
    host, port, frames_path, out_path = sys.argv[1:5]
    frames = np.load(frames_path)
    ros = roslibpy.Ros(host, int(port))
    ros.run(timeout=10)
    received = threading.Event()
    stop = threading.Event()

    def on_encoded(message: dict[str, object]) -> None:
        if received.is_set():
            return
        with open(out_path, "wb") as out:
            out.write(base64.b64decode(str(message["data"])))
        fields = {key: message[key] for key in ("width", "height", "encoding", "step")}
        print(json.dumps(fields), flush=True)
        received.set()

    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    roslibpy.Topic(ros, "/depthcloud_encoded", "sensor_msgs/Image").subscribe(on_encoded)
    depth = roslibpy.Topic(ros, "/camera/depth", "sensor_msgs/Image")
    rgb = roslibpy.Topic(ros, "/camera/rgb", "sensor_msgs/Image")
    deadline = time.monotonic() + LIMIT_S
    sec = 1
    while not stop.is_set() and time.monotonic() < deadline:
        depth.publish(roslibpy.Message(image(frames["depth"], "32FC1", sec)))
        rgb.publish(roslibpy.Message(image(frames["rgb"], "rgb8", sec)))
        sec += 1
        stop.wait(0.1)
    ros.terminate()
    return 0 if received.is_set() else 2


if __name__ == "__main__":
    sys.exit(main())
