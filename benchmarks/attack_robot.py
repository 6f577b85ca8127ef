"""The robot of the attack replays: a rosbridge client (from 127.0.0.3) that puts what a
class needs on the server's graph, a camera or 2,000 topics, on a thread of its own.

It connects over the WebSocket with the ``websockets`` library (never importing rwt,
so any server's version works), advertises, and publishes prepared CBOR frames
(binary frames, D27: an image's data as bytes) at a steady rate until the attack's
context closes it.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import AsyncIterator
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import Any

import anyio.to_thread
import cbor2
import numpy as np
from websockets.sync.client import ClientConnection, connect

__all__ = ["ROBOT_HOST", "camera_publisher", "compressed_publisher", "topics_advertised"]

ROBOT_HOST = "127.0.0.3"
TIMEOUT_S = 60.0


def _connect(ws_url: str) -> ClientConnection:
    return connect(ws_url, source_address=(ROBOT_HOST, 0), open_timeout=TIMEOUT_S, max_size=None)


def _settle(ws: ClientConnection, tag: str) -> None:
    """Wait until the server handled everything sent before (a call's answer)."""
    ws.send(json.dumps({"op": "call_service", "service": "/rosapi/get_time", "id": tag}))
    while True:
        frame = ws.recv(TIMEOUT_S)
        if isinstance(frame, str) and f'"{tag}"' in frame:
            return


class _Publisher:
    """Advertise ``topic`` as ``kind`` and publish ``frames`` in turn at ``hz``."""

    def __init__(self, ws_url: str, topic: str, kind: str, frames: list[bytes], hz: float) -> None:
        self.ws = _connect(ws_url)
        self.ws.send(json.dumps({"op": "advertise", "topic": topic, "type": kind}))
        _settle(self.ws, "advertised")
        self.frames, self.hz = frames, hz
        self.stop = threading.Event()
        self.sent = 0
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        due = time.monotonic()
        try:
            while not self.stop.is_set():
                self.ws.send(self.frames[self.sent % len(self.frames)])
                self.sent += 1
                due = max(due + 1 / self.hz, time.monotonic())
                self.stop.wait(max(0.0, due - time.monotonic()))
        except OSError:  # the server went away (the class's end)
            return

    def close(self) -> None:
        self.stop.set()
        self.thread.join(TIMEOUT_S)
        self.ws.close()


@asynccontextmanager
async def _publishing(
    ws_url: str, topic: str, kind: str, frames: list[bytes], hz: float
) -> AsyncIterator[_Publisher]:
    publisher = await anyio.to_thread.run_sync(_Publisher, ws_url, topic, kind, frames, hz)
    try:
        yield publisher
    finally:
        await anyio.to_thread.run_sync(publisher.close)


def _publish_op(topic: str, msg: dict[str, Any]) -> bytes:
    return cbor2.dumps({"op": "publish", "topic": topic, "msg": msg})


def camera_publisher(
    ws_url: str, topic: str, size: tuple[int, int], hz: float
) -> AbstractAsyncContextManager[_Publisher]:
    """A ``mono8`` ``sensor_msgs/msg/Image`` camera of ``size`` (width, height) at ``hz``:
    four frames of a moving gradient in turn (the encoders have something to encode)."""
    width, height = size
    x = np.arange(width, dtype=np.uint16)[np.newaxis, :]
    y = np.arange(height, dtype=np.uint16)[:, np.newaxis]
    frames = []
    for shift in range(4):
        pixels = ((x + y + shift * 37) % 256).astype(np.uint8)
        image = {
            "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "camera"},
            "height": height,
            "width": width,
            "encoding": "mono8",
            "is_bigendian": 0,
            "step": width,
            "data": pixels.tobytes(),
        }
        frames.append(_publish_op(topic, image))
    return _publishing(ws_url, topic, "sensor_msgs/msg/Image", frames, hz)


def compressed_publisher(
    ws_url: str, topic: str, image_format: str, data: bytes, hz: float
) -> AbstractAsyncContextManager[_Publisher]:
    """A ``sensor_msgs/msg/CompressedImage`` topic carrying ``data`` at ``hz``."""
    msg = {"header": {"frame_id": "camera"}, "format": image_format, "data": data}
    frames = [_publish_op(topic, msg)]
    return _publishing(ws_url, topic, "sensor_msgs/msg/CompressedImage", frames, hz)


class _Advertiser:
    def __init__(self, ws_url: str, names: list[str], kind: str) -> None:
        self.ws = _connect(ws_url)
        for name in names:
            self.ws.send(json.dumps({"op": "advertise", "topic": name, "type": kind}))
        _settle(self.ws, "advertised")


@asynccontextmanager
async def topics_advertised(
    ws_url: str, names: list[str], kind: str = "std_msgs/msg/String"
) -> AsyncIterator[None]:
    """``names`` advertised by one connection, for as long as the context lasts."""
    advertiser = await anyio.to_thread.run_sync(_Advertiser, ws_url, names, kind)
    try:
        yield
    finally:
        await anyio.to_thread.run_sync(advertiser.ws.close)
