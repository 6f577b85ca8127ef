"""Many MJPEG viewers of one camera: one encode per frame and per stream for all of them,
at most ``encoder_threads`` frames encoded at once over every stream, and a rosbridge
client on the same graph answered all along (docs/video.md, "Shared encoders and slow
viewers"; docs/limits.md, "HTTP video server").

Encodings are counted through a hook on ``StillEncoder.encode`` (the encoder every
MJPEG stream runs), which also records how many run at once.
"""

from __future__ import annotations

import contextlib
import io
import threading
import time

import anyio
import numpy as np
import pytest
from PIL import Image

from rwt_graph.graph import Graph
from rwt_graph.media import array_to_image
from rwt_video import encoders
from tests.support.clients import Client, is_op, running_server
from tests.video.support import TIMEOUT_S, camera, solid, video_server

from .test_video_server import PartReader

pytestmark = pytest.mark.anyio

VIEWERS = 16


class EncodeProbe:
    """Counts the calls of ``StillEncoder.encode`` and the most running at once.

    ``hold_s`` keeps each call in its thread a little longer, so that encodes that
    may overlap do (a wider window, not a measurement).
    """

    def __init__(self, monkeypatch: pytest.MonkeyPatch, hold_s: float = 0.0) -> None:
        self.calls = 0
        self.running = 0
        self.most_at_once = 0
        self._lock = threading.Lock()
        real = encoders.StillEncoder.encode

        def encode(encoder: encoders.StillEncoder, msg: encoders.Message) -> list[encoders.Part]:
            with self._lock:
                self.calls += 1
                self.running += 1
                self.most_at_once = max(self.most_at_once, self.running)
            try:
                time.sleep(hold_s)
                return real(encoder, msg)
            finally:
                with self._lock:
                    self.running -= 1

        monkeypatch.setattr(encoders.StillEncoder, "encode", encode)


async def echo_ready(client: Client) -> None:
    """Make ``client`` publish and subscribe ``/echo``, for ``echo_round_trips``."""
    await client.send({"op": "advertise", "topic": "/echo", "type": "std_msgs/msg/String"})
    await client.send({"op": "subscribe", "topic": "/echo", "type": "std_msgs/msg/String"})


async def echo_round_trips(client: Client, count: int) -> int:
    """``count`` publish -> subscribe round trips through the server; how many came back."""
    answered = 0
    for index in range(count):
        text = f"ping {index}"
        await client.send({"op": "publish", "topic": "/echo", "msg": {"data": text}})
        await client.expect(lambda m, text=text: is_op("publish")(m) and m["msg"]["data"] == text)
        answered += 1
    return answered


def grey(level: int) -> np.ndarray:
    pixels = np.empty((48, 64, 3), dtype=np.uint8)
    pixels[:] = level
    return pixels


def level_of(jpeg: bytes) -> int:
    """The grey level of a solid JPEG frame (JPEG keeps a flat image within a step or two)."""
    with Image.open(io.BytesIO(jpeg)) as picture:
        return round(float(np.asarray(picture).mean()))


async def test_sixteen_streams_encode_within_the_thread_bound_and_a_client_is_served(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # 16 viewers, each of its own quality: 16 distinct streams (encoders) of one camera
    probe = EncodeProbe(monkeypatch, hold_s=0.01)
    graph = Graph()
    got = [0] * VIEWERS
    async with (
        running_server(graph=graph) as harness,
        video_server(graph, encoder_threads=2) as client,
        camera(graph, "/cam", solid((10, 120, 230), 320, 240)),
    ):
        bystander = await harness.connect("ws")
        await echo_ready(bystander)

        async def watch(index: int) -> None:
            params = {"topic": "/cam", "type": "mjpeg", "quality": str(80 + index)}
            async with client.stream("GET", "/stream", params=params) as response:
                assert response.status_code == 200
                reader = PartReader(response)
                for _ in range(3):
                    headers, _data = await reader.part()
                    assert headers["content-type"] == "image/jpeg"
                    got[index] += 1

        with anyio.fail_after(TIMEOUT_S * 3):
            async with anyio.create_task_group() as viewers:
                for index in range(VIEWERS):
                    viewers.start_soon(watch, index)
                answered = await echo_round_trips(bystander, 20)  # while they watch
    assert got == [3] * VIEWERS  # every viewer was served
    assert answered == 20  # and so was the rosbridge client
    assert probe.calls >= VIEWERS  # each stream encoded its own frames...
    assert probe.most_at_once <= 2  # ...never more than the bound at once


async def test_sixteen_viewers_of_one_stream_share_one_encode_per_frame(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    probe = EncodeProbe(monkeypatch)
    graph = Graph()
    publisher = graph.create_publisher("/cam", "sensor_msgs/msg/Image")
    levels = [20 * step for step in range(1, 7)]  # one distinct grey a frame
    params = {"topic": "/cam", "type": "mjpeg", "quality": "90"}
    async with (
        running_server(graph=graph) as harness,
        video_server(graph) as client,
        contextlib.AsyncExitStack() as viewers,
    ):
        bystander = await harness.connect("ws")
        await echo_ready(bystander)
        readers = []
        with anyio.fail_after(TIMEOUT_S * 3):
            for _ in range(VIEWERS):  # its headers came: the viewer is on the stream
                stream = client.stream("GET", "/stream", params=params)
                readers.append(PartReader(await viewers.enter_async_context(stream)))
            assert len(graph.topics["/cam"].subscribers) == 1  # one stream for all
            for level in levels:
                publisher.publish(array_to_image(grey(level), "rgb8"))
                for reader in readers:  # every viewer gets this frame before the next is sent
                    assert abs(level_of((await reader.part())[1]) - level) <= 2
                assert await echo_round_trips(bystander, 1) == 1
    assert probe.calls == len(levels)  # one encode a frame for all 16 viewers
