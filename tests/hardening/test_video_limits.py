"""The HTTP video server's caps: one request or a few viewers cannot exhaust it (docs/limits.md).

Every test runs a real ``serve_video`` server on 127.0.0.1 with httpx or raw sockets
and checks that, after the hostile request, another viewer is still served.
"""

from __future__ import annotations

import socket

import anyio
import anyio.to_thread
import httpx
import numpy as np
import pytest

from rwt_graph.graph import Graph
from rwt_video import encoders
from rwt_video.params import MAX_BITRATE, MAX_PIXELS, MAX_SIDE
from tests.video.support import TIMEOUT_S, camera, solid, video_server

pytestmark = pytest.mark.anyio


async def assert_snapshot_served(client: httpx.AsyncClient, topic: str = "/cam") -> None:
    """A healthy viewer still gets a JPEG."""
    with anyio.fail_after(TIMEOUT_S):
        reply = await client.get("/snapshot", params={"topic": topic})
    assert reply.status_code == 200
    assert reply.headers["content-type"] == "image/jpeg"


@pytest.mark.parametrize(
    ("query", "reason"),
    [
        ({"width": "1073741824", "height": "1073741824"}, f"outside -1..{MAX_SIDE}"),
        ({"width": str(MAX_SIDE), "height": str(MAX_SIDE)}, f"over {MAX_PIXELS} pixels"),
        ({"width": "9" * 5000}, "is not an integer"),
        ({"height": "1e400"}, "is not an integer"),
        ({"width": "NaN"}, "is not an integer"),
        ({"width": "-5"}, "outside -1.."),
        ({"quality": "100000"}, "outside 1..100"),
        ({"type": "vp8", "bitrate": str(MAX_BITRATE + 1)}, "outside 1.."),
        ({"type": "vp8", "gop": "100000"}, "outside 1..1000"),
        ({"type": "vp8", "qmin": "50", "qmax": "10"}, "qmin=50 is above qmax=10"),
    ],
)
async def test_out_of_range_parameters_get_400_with_the_reason(
    query: dict[str, str], reason: str
) -> None:
    graph = Graph()
    async with video_server(graph) as client, camera(graph, "/cam", solid((10, 20, 30), 64, 48)):
        for path in ("/snapshot", "/stream"):
            reply = await client.get(path, params={"topic": "/cam", **query})
            assert reply.status_code == 400, (path, reply.text)
            assert reason in reply.text
            assert len(reply.content) < 200  # a huge value is not echoed back
        await assert_snapshot_served(client)


async def test_upscaling_a_large_image_past_the_pixel_budget_is_skipped() -> None:
    # Only the width is given: the height is the image's own (3000), so the frame
    # would be 4000 x 3000, over the budget; the frame is skipped, not encoded.
    graph = Graph()
    async with (
        video_server(graph, snapshot_timeout_s=0.5) as client,
        camera(graph, "/tall", solid((1, 2, 3), 8, 3000)),
        camera(graph, "/cam", solid((10, 20, 30), 64, 48)),
    ):
        reply = await client.get("/snapshot", params={"topic": "/tall", "width": "4000"})
        assert reply.status_code == 503
        await assert_snapshot_served(client)
        small = await client.get("/snapshot", params={"topic": "/tall", "width": "16"})
        assert small.status_code == 200


async def test_an_encoder_that_fails_skips_the_frame_and_the_server_goes_on(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    real_encode = encoders.StillEncoder.encode
    failures = 0

    def encode_or_fail(self: encoders.StillEncoder, msg: object) -> object:
        nonlocal failures
        if failures < 3:
            failures += 1
            raise MemoryError("injected")
        return real_encode(self, msg)  # type: ignore[arg-type]

    monkeypatch.setattr(encoders.StillEncoder, "encode", encode_or_fail)
    graph = Graph()
    async with video_server(graph) as client, camera(graph, "/cam", solid((10, 20, 30), 64, 48)):
        await assert_snapshot_served(client)
    assert failures == 3


async def test_connections_over_the_cap_get_503_and_the_server_recovers() -> None:
    graph = Graph()
    async with (
        video_server(graph, max_connections=3) as client,
        camera(graph, "/cam", solid((10, 20, 30), 64, 48)),
    ):
        port = httpx.URL(str(client.base_url)).port
        idle = [socket.create_connection(("127.0.0.1", port)) for _ in range(3)]
        try:
            await anyio.sleep(0.2)  # let the server accept them (no reply to wait for)
            extra = socket.create_connection(("127.0.0.1", port))
            extra.settimeout(TIMEOUT_S)
            answer = await anyio.to_thread.run_sync(extra.recv, 1024)
            extra.close()
            assert answer.startswith(b"HTTP/1.1 503")
            assert b"too many connections" in answer
        finally:
            for sock in idle:
                sock.close()
        with anyio.fail_after(TIMEOUT_S):
            while True:  # the idle ones are released once the server sees them close
                reply = await client.get("/snapshot", params={"topic": "/cam"})
                if reply.status_code == 200:
                    break
                await anyio.sleep(0.05)


async def test_distinct_streams_over_the_cap_get_503() -> None:
    graph = Graph()
    async with (
        video_server(graph, max_streams=1) as client,
        camera(graph, "/cam", solid((10, 20, 30), 64, 48)),
    ):
        with anyio.fail_after(TIMEOUT_S):
            async with client.stream(
                "GET", "/stream", params={"topic": "/cam", "quality": "50"}
            ) as first:
                assert first.status_code == 200
                other = await client.get("/snapshot", params={"topic": "/cam", "quality": "60"})
                assert other.status_code == 503
                assert "1 distinct streams run already" in other.text
                same = await client.get("/snapshot", params={"topic": "/cam", "quality": "50"})
                assert same.status_code == 200  # the running stream is shared
        await assert_snapshot_served(client)


async def test_hostile_image_messages_are_skipped() -> None:
    # A publisher's image whose size does not match its data is refused frame by frame.
    graph = Graph()
    publisher = graph.create_publisher("/bad", "sensor_msgs/msg/Image", latch=True)
    async with (
        video_server(graph, snapshot_timeout_s=0.3) as client,
        camera(graph, "/cam", solid((10, 20, 30), 64, 48)),
    ):
        huge = {"height": 1 << 30, "width": 1 << 30, "encoding": "rgb8", "step": 3 << 30}
        publisher.publish({**huge, "data": np.zeros(12, dtype=np.uint8).tobytes()})
        reply = await client.get("/snapshot", params={"topic": "/bad"})
        assert reply.status_code == 503
        await assert_snapshot_served(client)
