"""``rwt serve --video --depthcloud``: roslibpy publishes depth and colour, receives the
encoded depth cloud as an Image topic (as ros3djs users subscribe), and an HTTP client
reads the same topic as an MJPEG stream from the video port and rebuilds the depth."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from PIL import Image

from rwt_graph.media import decode_depthcloud
from tests.integration.client_harness import HERE, ServerProcess

TIMEOUT_S = 20.0
WIDTH, HEIGHT, TILE = 320, 240, 256


def scene() -> tuple[np.ndarray, np.ndarray]:
    """A tilted wall 0.6..1.6 m with a hole, and a colour gradient."""
    columns = np.linspace(0.6, 1.6, WIDTH, dtype=np.float32)
    depth = np.repeat(columns[np.newaxis, :], HEIGHT, axis=0)
    depth[100:140, 150:200] = np.nan
    rgb = np.zeros((HEIGHT, WIDTH, 3), dtype=np.uint8)
    rgb[..., 0] = np.linspace(0, 255, WIDTH, dtype=np.uint8)
    rgb[..., 2] = 120
    return depth, rgb


@pytest.fixture
def video_server(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[str, str]]:
    args = ("--video", "--video-port", "0", "--depthcloud", "/camera/depth,/camera/rgb")
    server = ServerProcess(tmp_path, (*args, "--depthcloud-tile-size", str(TILE)))
    request.node._rwt_server = server
    try:
        video_line = server.next_stdout_line()
        assert video_line is not None and video_line.startswith("video on http://"), video_line
        yield server.url, video_line.removeprefix("video on ")
    finally:
        server.stop()


def test_depthcloud_reaches_roslibpy_and_the_mjpeg_stream(
    video_server: tuple[str, str], tmp_path: Path
) -> None:
    ws_url, http_url = video_server
    host, port = ws_url.removeprefix("ws://").rsplit(":", 1)
    depth, rgb = scene()
    np.savez(tmp_path / "frames.npz", depth=depth, rgb=rgb)
    out = tmp_path / "encoded.bin"
    client = subprocess.Popen(
        [sys.executable, str(HERE / "roslibpy_depthcloud.py"), host, port, "frames.npz", str(out)],
        cwd=tmp_path,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        assert client.stdout is not None and client.stdin is not None
        fields = json.loads(client.stdout.readline() or b"{}")  # the script is bounded (30 s)
        side = 2 * TILE
        assert fields == {"width": side, "height": side, "encoding": "bgr8", "step": 3 * side}
        params = {"topic": "/depthcloud_encoded", "type": "mjpeg", "quality": "95"}
        with httpx.stream("GET", f"{http_url}/stream", params=params, timeout=TIMEOUT_S) as stream:
            data = b""
            for chunk in stream.iter_bytes():
                data += chunk
                if data.count(b"--boundarydonotcross") >= 2:
                    break
        client.stdin.close()
        assert client.wait(TIMEOUT_S) == 0, client.stderr.read() if client.stderr else ""
    finally:
        client.kill()
        client.wait()
        for pipe in (client.stdin, client.stdout, client.stderr):
            if pipe is not None:
                pipe.close()

    # the Image message roslibpy received: lossless, within half a quantisation step
    tiles = np.frombuffer(out.read_bytes(), dtype=np.uint8).reshape(2 * TILE, 2 * TILE, 3)
    exact = decode_depthcloud(tiles, width=WIDTH, height=HEIGHT)
    kept = np.s_[:, 32:288]  # 320 columns centred in a 256 tile
    expected_valid = np.isfinite(depth)
    assert (exact.valid[kept] == expected_valid[kept]).all()
    assert np.nanmax(np.abs(exact.depth - depth)) <= 1 / 1530 + 1e-6
    assert (exact.colour[kept] == rgb[kept]).all()

    # the MJPEG part (browsers show it as RGB; the message bytes are BGR order)
    part = data.split(b"\r\n\r\n", 1)[1]
    jpeg = part[: part.index(b"\r\n--boundarydonotcross")]
    shown = np.asarray(Image.open(io.BytesIO(jpeg)).convert("RGB"))
    lossy = decode_depthcloud(shown[..., ::-1].copy(), width=WIDTH, height=HEIGHT, tolerance=8)
    both = lossy.valid & exact.valid
    assert both.sum() >= 0.95 * exact.valid.sum()
    error_mm = np.abs(lossy.depth - depth)[both] * 1000
    assert np.median(error_mm) < 5.0
