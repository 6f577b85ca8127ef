"""The HTTP video server with real HTTP clients (httpx, a raw socket), Pillow and PyAV decoding."""

from __future__ import annotations

import io
import socket

import anyio
import anyio.to_thread
import av
import httpx
import numpy as np
import pytest
from PIL import Image

from rwt_graph.graph import Graph
from rwt_graph.media import array_to_image
from tests.video.support import TIMEOUT_S, Frame, camera, solid, video_server

pytestmark = pytest.mark.anyio

BOUNDARY = b"--boundarydonotcross"


def halves(width: int = 64, height: int = 48) -> Frame:
    """Left half red, right half blue: shows inversion."""
    pixels = np.zeros((height, width, 3), dtype=np.uint8)
    pixels[:, : width // 2] = (255, 0, 0)
    pixels[:, width // 2 :] = (0, 0, 255)
    return lambda index: pixels


class PartReader:
    """Reads a multipart/x-mixed-replace body part by part (one iterator for the response)."""

    def __init__(self, response: httpx.Response) -> None:
        self._chunks = response.aiter_bytes()
        self._buffer = b""

    async def parts(self, count: int) -> list[tuple[dict[str, str], bytes]]:
        """The next ``count`` parts: (headers in lower case, body)."""
        return [await self.part() for _ in range(count)]

    async def part(self) -> tuple[dict[str, str], bytes]:
        while True:
            buffer = self._buffer
            start = buffer.find(BOUNDARY + b"\r\n")
            head_end = buffer.find(b"\r\n\r\n", start + 1) if start >= 0 else -1
            if head_end >= 0:
                lines = buffer[start + len(BOUNDARY) + 2 : head_end].decode().split("\r\n")
                headers = {k.lower(): v.strip() for k, v in (line.split(":", 1) for line in lines)}
                end = head_end + 4 + int(headers["content-length"])
                if len(buffer) >= end + 2:
                    self._buffer = buffer[end + 2 :]
                    return headers, buffer[head_end + 4 : end]
            self._buffer += await self._chunks.__anext__()


async def read_parts(response: httpx.Response, count: int) -> list[tuple[dict[str, str], bytes]]:
    """The first ``count`` parts of a response read only here."""
    return await PartReader(response).parts(count)


def decode_frames(data: bytes) -> list[np.ndarray]:
    """Frames PyAV decodes from a (possibly cut) video stream."""
    frames = []
    try:
        for frame in av.open(io.BytesIO(data)).decode(video=0):
            frames.append(frame.to_ndarray(format="rgb24"))
    except av.FFmpegError:
        pass  # too short yet, or cut mid-packet
    return frames


async def read_video(client: httpx.AsyncClient, frames: int, **params: str) -> list[np.ndarray]:
    async with client.stream("GET", "/stream", params=params) as response:
        assert response.status_code == 200
        expected = "video/mp4" if params["type"] == "h264" else "video/webm"
        assert response.headers["content-type"] == expected
        data = b""
        async for chunk in response.aiter_bytes():
            data += chunk
            decoded = decode_frames(data)
            if len(decoded) >= frames:
                return decoded
    raise AssertionError("the stream ended")


async def test_mjpeg_stream_parts_decode_as_the_published_image() -> None:
    graph = Graph()
    async with video_server(graph) as client, camera(graph, "/cam", solid((200, 40, 90))):
        with anyio.fail_after(TIMEOUT_S):
            async with client.stream("GET", "/stream", params={"topic": "/cam"}) as response:
                assert response.status_code == 200
                assert response.headers["content-type"] == (
                    "multipart/x-mixed-replace;boundary=boundarydonotcross"
                )
                assert response.headers["access-control-allow-origin"] == "*"
                parts = await read_parts(response, 3)
    for headers, data in parts:
        assert headers["content-type"] == "image/jpeg"
        float(headers["x-timestamp"])
        picture = Image.open(io.BytesIO(data))
        assert picture.format == "JPEG" and picture.size == (640, 480)
        assert np.abs(np.asarray(picture).astype(int) - (200, 40, 90)).max() <= 6


async def test_snapshot_resizes_and_inverts() -> None:
    graph = Graph()
    async with video_server(graph) as client, camera(graph, "/cam", halves()):
        with anyio.fail_after(TIMEOUT_S):
            plain = await client.get("/snapshot", params={"topic": "/cam"})
            turned = await client.get(
                "/snapshot", params={"topic": "cam", "invert": "", "width": "32", "height": "24"}
            )
    assert plain.status_code == 200 and plain.headers["content-type"] == "image/jpeg"
    assert int(plain.headers["content-length"]) == len(plain.content)
    left_red = np.asarray(Image.open(io.BytesIO(plain.content)))
    assert left_red.shape == (48, 64, 3) and left_red[24, 5, 0] > 200 and left_red[24, 60, 2] > 200
    left_blue = np.asarray(Image.open(io.BytesIO(turned.content)))
    assert left_blue.shape == (24, 32, 3)
    assert left_blue[12, 2, 2] > 200 and left_blue[12, 30, 0] > 200


async def test_png_stream_is_lossless_and_scales_depth() -> None:
    graph = Graph()
    depth = np.array([[0.0, 1.0], [2.0, 4.0]], dtype=np.float32)
    async with video_server(graph) as client, camera(graph, "/depth", lambda i: depth, "32FC1"):
        with anyio.fail_after(TIMEOUT_S):
            params = {"topic": "/depth", "type": "png"}
            async with client.stream("GET", "/stream", params=params) as response:
                [(headers, data)] = await read_parts(response, 1)
    assert headers["content-type"] == "image/png"
    shown = np.asarray(Image.open(io.BytesIO(data)))
    assert shown[..., 0].tolist() == [[0, 63], [127, 255]]  # the maximum maps to 255


async def test_ros_compressed_passes_the_compressed_topic_through() -> None:
    graph = Graph()
    jpeg = io.BytesIO()
    Image.new("RGB", (8, 8), (1, 2, 3)).save(jpeg, "JPEG")
    compressed = graph.create_publisher("/cam/compressed", "sensor_msgs/msg/CompressedImage")
    graph.create_publisher("/cam", "sensor_msgs/msg/Image")
    async with video_server(graph) as client:
        with anyio.fail_after(TIMEOUT_S):
            async with client.stream(
                "GET", "/stream", params={"topic": "/cam", "type": "ros_compressed"}
            ) as response:
                compressed.publish({"format": "jpeg", "data": jpeg.getvalue()})
                [(headers, data)] = await read_parts(response, 1)
    assert headers["content-type"] == "image/jpeg" and data == jpeg.getvalue()


async def test_ros_compressed_without_a_compressed_topic_falls_back_to_mjpeg() -> None:
    graph = Graph()
    async with video_server(graph) as client, camera(graph, "/cam", halves()):
        with anyio.fail_after(TIMEOUT_S):
            params = {"topic": "/cam", "type": "ros_compressed"}
            async with client.stream("GET", "/stream", params=params) as response:
                [(headers, data)] = await read_parts(response, 1)
    assert headers["content-type"] == "image/jpeg"
    assert Image.open(io.BytesIO(data)).size == (64, 48)


@pytest.mark.parametrize("codec", ["vp8", "vp9"])
async def test_webm_stream_decodes_with_pyav(codec: str) -> None:
    graph = Graph()
    async with video_server(graph) as client, camera(graph, "/cam", solid((30, 160, 220))):
        with anyio.fail_after(TIMEOUT_S):
            frames = await read_video(
                client, 5, topic="/cam", type=codec, width="320", height="240", bitrate="300000"
            )
    assert all(frame.shape == (240, 320, 3) for frame in frames)
    assert np.abs(frames[-1].astype(int).mean(axis=(0, 1)) - (30, 160, 220)).max() <= 12


async def test_h264_stream_decodes_with_pyav() -> None:
    graph = Graph()
    async with video_server(graph) as client, camera(graph, "/cam", solid((220, 200, 20))):
        with anyio.fail_after(TIMEOUT_S):
            frames = await read_video(client, 5, topic="/cam", type="h264")
    assert all(frame.shape == (480, 640, 3) for frame in frames)
    assert np.abs(frames[-1].astype(int).mean(axis=(0, 1)) - (220, 200, 20)).max() <= 12


async def test_a_late_vp8_viewer_starts_at_a_keyframe() -> None:
    graph = Graph()
    async with video_server(graph) as client, camera(graph, "/cam", solid((90, 90, 200))):
        with anyio.fail_after(TIMEOUT_S):
            async with client.stream("GET", "/stream", params={"topic": "/cam", "type": "vp8"}):
                late = await read_video(client, 3, topic="/cam", type="vp8")
    assert len(late) >= 3 and late[0].shape == (480, 640, 3)


async def test_viewers_of_the_same_stream_share_one_subscription() -> None:
    graph = Graph()

    def subscribers() -> int:
        return len(graph.topics["/cam"].subscribers)

    async with video_server(graph) as client, camera(graph, "/cam", halves()):
        with anyio.fail_after(TIMEOUT_S):
            same = {"topic": "/cam", "quality": "50"}
            async with client.stream("GET", "/stream", params=same) as first:
                first_parts = PartReader(first)
                await first_parts.part()
                async with client.stream("GET", "/stream", params=same) as second:
                    second_parts = PartReader(second)
                    await second_parts.part()
                    assert subscribers() == 1
                    other = {"topic": "/cam", "quality": "60"}
                    async with client.stream("GET", "/stream", params=other) as third:
                        await PartReader(third).part()
                        assert subscribers() == 2
                    await first_parts.part()  # still streaming
                    await second_parts.part()
            while subscribers():  # the last viewer gone, the stream unsubscribes
                await anyio.sleep(0.01)


def noise_frames() -> Frame:
    """Incompressible 640x480 frames (about 900 KB as PNG); pixel (0, 0) holds the index."""
    rng = np.random.default_rng(7)
    base = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)

    def frame(index: int) -> np.ndarray:
        pixels = np.roll(base, index, axis=1)
        pixels[0, 0] = (index % 256, 0, 0)
        return pixels

    return frame


class StalledViewer:
    """A raw-socket HTTP/1.0 viewer with a small receive buffer; it stops reading after
    the response headers until told to resume."""

    def __init__(self, url: str, path: str) -> None:
        host, port = url.removeprefix("http://").rsplit(":", 1)
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 16384)
        self.sock.settimeout(TIMEOUT_S)
        self.sock.connect((host, int(port)))
        self.sock.sendall(f"GET {path} HTTP/1.0\r\n\r\n".encode())
        self.buffer = b""
        while b"\r\n\r\n" not in self.buffer:
            self.buffer += self.sock.recv(4096)
        self.buffer = self.buffer.split(b"\r\n\r\n", 1)[1]

    def read_until_frame(self, index: int) -> int:
        """Resume reading; the number of parts received when frame ``index`` arrives."""
        parts = 0
        while True:
            start = self.buffer.find(BOUNDARY + b"\r\n")
            head_end = self.buffer.find(b"\r\n\r\n", start + 1) if start >= 0 else -1
            if head_end >= 0:
                head = self.buffer[start:head_end].decode()
                size = int(head.rsplit("Content-Length: ", 1)[1])
                end = head_end + 4 + size
                if len(self.buffer) >= end:
                    data, self.buffer = self.buffer[head_end + 4 : end], self.buffer[end:]
                    parts += 1
                    with Image.open(io.BytesIO(data)) as picture:
                        if picture.getpixel((0, 0))[0] == index:  # type: ignore[index]
                            return parts
                    continue
            self.buffer += self.sock.recv(1 << 20)

    def close(self) -> None:
        self.sock.close()


async def test_a_stalled_viewer_does_not_slow_another_viewer() -> None:
    graph = Graph()
    frame = noise_frames()
    publisher = graph.create_publisher("/noise", "sensor_msgs/msg/Image")
    last = 30
    async with video_server(graph) as client:
        path = "/stream?topic=/noise&type=png&quality=1"
        stalled = await anyio.to_thread.run_sync(StalledViewer, str(client.base_url), path)
        try:
            with anyio.fail_after(TIMEOUT_S * 3):
                params = {"topic": "/noise", "type": "png", "quality": "1"}
                async with client.stream("GET", "/stream", params=params) as response:
                    reader = PartReader(response)
                    publisher.publish(array_to_image(frame(0), "rgb8"))
                    await reader.part()  # both viewers are on the stream
                    for index in range(1, last + 1):
                        publisher.publish(array_to_image(frame(index), "rgb8"))
                        await anyio.sleep(0.005)  # pacing, not synchronisation
                    seen = -1
                    while seen != last:  # the reading viewer gets the newest frame...
                        _, data = await reader.part()
                        seen = Image.open(io.BytesIO(data)).getpixel((0, 0))[0]  # type: ignore[index]
                # ...while the other has not read a byte; once it reads, it skipped frames
                parts = await anyio.to_thread.run_sync(stalled.read_until_frame, last)
        finally:
            stalled.close()
    assert parts < last


async def test_errors_answer_with_a_status() -> None:
    graph = Graph()
    graph.create_publisher("/chatter", "std_msgs/msg/String")
    graph.create_publisher("/cam", "sensor_msgs/msg/Image")
    async with video_server(graph, snapshot_timeout_s=0.2) as client:
        cases = {
            "/stream?topic=/nothing": (404, "does not exist"),
            "/stream?topic=/cam&type=theora": (404, "unknown stream type"),
            "/stream?topic=/chatter": (400, "not a sensor_msgs/Image"),
            "/stream?topic=/cam&quality=high": (400, "not an integer"),
            "/stream?topic=/cam&quality=101": (400, "outside 1..100"),
            "/stream": (400, "missing query parameter topic"),
            "/snapshot?topic=/cam": (503, "no image on /cam"),
            "/elsewhere": (404, "no page"),
        }
        with anyio.fail_after(TIMEOUT_S):
            for path, (status, text) in cases.items():
                response = await client.get(path)
                assert (response.status_code, text in response.text) == (status, True), path
            posted = await client.post("/stream?topic=/cam")
    assert posted.status_code == 405


async def test_topic_list_and_viewer_pages() -> None:
    graph = Graph()
    graph.create_publisher("/camera/image_raw", "sensor_msgs/msg/Image")
    graph.create_publisher("/camera/camera_info", "sensor_msgs/msg/CameraInfo")
    graph.create_publisher("/other", "sensor_msgs/msg/Image")
    graph.create_publisher("/chatter", "std_msgs/msg/String")
    async with video_server(graph) as client:
        with anyio.fail_after(TIMEOUT_S):
            listing = (await client.get("/")).text
            video = (await client.get("/stream_viewer?topic=/other&type=vp8")).text
            still = (await client.get("/stream_viewer?topic=/other")).text
    assert "<li>/camera/<ul><li>" in listing and ">image_raw</a>" in listing
    assert 'href="/snapshot?topic=%2Fother"' in listing and "chatter" not in listing
    assert '<video src="/stream?topic=%2Fother&amp;type=vp8"' in video
    assert '<img src="/stream?topic=%2Fother&amp;type=mjpeg"' in still
