"""A video server and a camera on one graph, for the video tests and the hardening ones."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import anyio
import httpx
import numpy as np

from rwt_graph.graph import Graph
from rwt_graph.media import array_to_image
from rwt_video import VideoConfig, serve_video

TIMEOUT_S = 20.0
Frame = Callable[[int], np.ndarray]


@asynccontextmanager
async def video_server(graph: Graph, **config: object) -> AsyncIterator[httpx.AsyncClient]:
    async with anyio.create_task_group() as tg:
        url = await tg.start(serve_video, graph, VideoConfig(port=0, **config))  # type: ignore[arg-type]
        async with httpx.AsyncClient(base_url=url, timeout=TIMEOUT_S) as client:
            yield client
        tg.cancel_scope.cancel()


@asynccontextmanager
async def camera(graph: Graph, topic: str, frame: Frame, encoding: str = "rgb8"):
    """Publish frame(i) on ``topic`` about 50 times a second while the block runs."""
    publisher = graph.create_publisher(topic, "sensor_msgs/msg/Image")

    async def run() -> None:
        index = 0
        while True:
            publisher.publish(array_to_image(frame(index), encoding))
            index += 1
            await anyio.sleep(0.02)  # pacing, not synchronisation

    async with anyio.create_task_group() as tg:
        tg.start_soon(run)
        yield publisher
        tg.cancel_scope.cancel()


def solid(rgb: tuple[int, int, int], width: int = 640, height: int = 480) -> Frame:
    pixels = np.empty((height, width, 3), dtype=np.uint8)
    pixels[:] = rgb
    return lambda index: pixels
