"""Image work: never more pixels than the server can afford, never on the event loop.

A compressed image is refused from its header when it would decode to more than
``MAX_DECODE_PIXELS`` (``rwt_graph.media.compressed``), and every front end's
image work runs in the image threads (``rwt_graph.media.threads``): the MCP
``echo`` of ``CompressedImage`` topics (the official MCP client against
``rwt serve --mcp`` in the test's process) and the depth-cloud encoder
(``--depthcloud``). The event loop's thread is the test's: what it spends is what
every other client of the server waits for.
"""

from __future__ import annotations

import io
import time

import anyio
import numpy as np
import pytest
from PIL import Image

from rwt import Graph, RosbridgeServer, ServerConfig
from rwt_graph.media import array_to_image
from rwt_graph.media.compressed import MAX_DECODE_PIXELS
from rwt_graph.media.depthcloud_node import DepthCloudEncoder

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp.types import ImageContent, TextContent

from tests.agents.test_rwt_mcp import rwt_serve_mcp
from tests.hardening.test_mcp_tools import serving

pytestmark = pytest.mark.anyio

COMPRESSED = "sensor_msgs/msg/CompressedImage"


def _text(result: object) -> str:
    content = getattr(result, "content", [])
    return " ".join(block.text for block in content if isinstance(block, TextContent))


def _png(image: Image.Image) -> bytes:
    out = io.BytesIO()
    image.save(out, "PNG")
    return out.getvalue()


async def test_an_image_bomb_is_refused_from_its_header() -> None:
    graph = Graph()
    camera = graph.create_publisher("/camera/compressed", COMPRESSED, latch=True)
    bomb = _png(Image.new("L", (6300, 6300)))  # 39 KB; 119 MB as the RGB it would become
    camera.publish({"format": "png", "data": bomb})
    async with serving(graph) as url, rwt_serve_mcp(url) as agent:
        with anyio.fail_after(20):  # main decoded it for seconds of CPU, then answered an image
            refused = await agent.result("echo", topic="/camera/compressed")
    assert refused.is_error
    assert _text(refused).endswith(
        f"/camera/compressed: a 6300x6300 image is over {MAX_DECODE_PIXELS} pixels"
        " (MAX_DECODE_PIXELS)"
    )


async def test_images_are_decoded_off_the_event_loop() -> None:
    """An echo of two 4K PNGs: their decoding is not the event loop's CPU (its clients')."""
    graph = Graph()
    camera = graph.create_publisher("/camera/compressed", COMPRESSED)
    x = np.arange(3840, dtype=np.uint8)[np.newaxis, :]  # uint8: the products wrap at 256
    y = np.arange(2160, dtype=np.uint8)[:, np.newaxis]
    pattern = np.empty((2160, 3840, 3), np.uint8)
    pattern[..., 0], pattern[..., 1], pattern[..., 2] = x * 7, y * 3, (x + y) * 5
    frame = {"format": "png", "data": _png(Image.fromarray(pattern))}
    async with serving(graph) as url, rwt_serve_mcp(url) as agent:

        async def keep_publishing() -> None:
            while True:
                camera.publish(frame)
                await anyio.sleep(0.05)

        async with anyio.create_task_group() as tg:
            tg.start_soon(keep_publishing)
            loop_cpu, all_cpu = time.thread_time(), time.process_time()
            echoed = await agent.result("echo", topic="/camera/compressed", count=2, timeout_s=30)
            loop_cpu, all_cpu = time.thread_time() - loop_cpu, time.process_time() - all_cpu
            tg.cancel_scope.cancel()
    images = [block for block in echoed.content if isinstance(block, ImageContent)]
    assert len(images) == 2 and images[0].mime_type == "image/jpeg"
    # each image: ~0.2 s of CPU to decode, scale and encode, all of it in an image thread
    # (main: all of it on the event loop, the loop's thread took ~all the process's CPU)
    assert loop_cpu < 0.5 * all_cpu, (loop_cpu, all_cpu)


async def test_the_depth_cloud_is_encoded_off_the_event_loop() -> None:
    """A 1920x1080 depth frame (about 0.15 s of CPU to encode): not on the event loop."""
    graph = Graph()
    DepthCloudEncoder(graph, "/depth", tile_size=512)
    depth = graph.create_publisher("/depth", "sensor_msgs/msg/Image")
    y, x = np.mgrid[0:1080, 0:1920]
    metres = (0.5 + (x + y) % 200 / 100).astype(np.float32)
    encoded: list[object] = []
    graph.create_subscription("/depthcloud_encoded", encoded.append, "sensor_msgs/msg/Image")
    async with anyio.create_task_group() as tg:
        await tg.start(RosbridgeServer(graph, ServerConfig(host="127.0.0.1", port=0)).serve)
        loop_cpu, all_cpu = time.thread_time(), time.process_time()
        depth.publish(array_to_image(metres, "32FC1"))
        with anyio.fail_after(30):
            while not encoded:
                await anyio.sleep(0.01)
        loop_cpu, all_cpu = time.thread_time() - loop_cpu, time.process_time() - all_cpu
        tg.cancel_scope.cancel()
    assert len(encoded) == 1
    # main: encoded in the graph's callback, on the event loop: ~all of the CPU there
    assert loop_cpu < 0.5 * all_cpu, (loop_cpu, all_cpu)
