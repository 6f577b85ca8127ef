"""The robot's MCP App in Chromium, rendered by the official MCP Apps host bridge.

A host page (tests/js/apphost: ``@modelcontextprotocol/ext-apps``' AppBridge and the
official MCP client, bundled) connects to ``rwt serve --mcp --webrtc --video``, calls
``robot_app``, reads the ``ui://`` resource the tool names and renders it in a
sandboxed frame under the CSP the resource declares, as a host does. A robot (a
rosbridge client) publishes a camera and records ``/cmd_vel``. The user sees the
camera, holds the pad with the mouse, and lets go: the robot gets Twists only while
it is held, then one zero Twist (docs/mcp.md, "The robot app").
"""

from __future__ import annotations

import base64
import io
import json
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from PIL import Image
from websockets.sync.client import ClientConnection, connect

from tests.integration.client_harness import ServerProcess
from tests.support.apphost import app_host
from tests.webrtc.pagesite import serve_pages

from .cdp import Browser, Page, wait_until

pytest.importorskip("aiortc", reason="the camera's WebRTC track needs aiortc (the webrtc extra)")
pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

HOST_DIR, _why = app_host()
if HOST_DIR is None:
    pytest.skip(_why, allow_module_level=True)

WIDTH, HEIGHT = 64, 48
RED, BLUE = (220, 30, 30), (30, 30, 220)
ARGS = {"camera": "/camera/image", "cmd_vel": "/cmd_vel", "max_linear": 0.5, "max_angular": 1.0}
# the app's layout (robot_app.html) in the frame (a 2 px border): 8 px of padding, the
# 320 px camera, 12 px, the pad
PAD_X, PAD_Y, PAD_SIZE = 2 + 8 + 320 + 12, 2 + 8, 180


class Robot:
    """A rosbridge client: a camera (left half red, right half blue) and a /cmd_vel log."""

    def __init__(self, ws: ClientConnection) -> None:
        self.twists: list[tuple[float, dict[str, Any]]] = []
        self.stop = threading.Event()
        self.ws = ws
        self.ws.send(json.dumps({"op": "advertise", "topic": ARGS["camera"], "type": IMAGE}))
        sub = {"op": "subscribe", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist"}
        self.ws.send(json.dumps(sub))
        self.threads = [threading.Thread(target=f, daemon=True) for f in (self._read, self._camera)]
        for thread in self.threads:
            thread.start()

    def _read(self) -> None:
        for frame in self.ws:
            message = json.loads(frame)
            if message.get("op") == "publish" and message.get("topic") == "/cmd_vel":
                self.twists.append((time.monotonic(), message["msg"]))

    def _camera(self) -> None:
        pixels = bytearray()
        for _ in range(HEIGHT):
            pixels += bytes(RED) * (WIDTH // 2) + bytes(BLUE) * (WIDTH // 2)
        data = base64.b64encode(bytes(pixels)).decode()
        image = {"height": HEIGHT, "width": WIDTH, "encoding": "rgb8", "step": WIDTH * 3}
        while not self.stop.wait(0.1):
            msg = {"header": {"frame_id": "camera"}, **image, "data": data}
            self.ws.send(json.dumps({"op": "publish", "topic": ARGS["camera"], "msg": msg}))

    def close(self) -> None:
        # the camera stops before the socket closes: a frame sent after would raise in its thread
        self.stop.set()
        self.threads[1].join(5)
        self.ws.close()
        self.threads[0].join(5)


IMAGE = "sensor_msgs/msg/Image"


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture
def robot(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[ServerProcess, Robot]]:
    """``rwt serve --mcp --video --webrtc`` and its robot (``no_webrtc`` marked: no --webrtc)."""
    video = ("--video", "--video-port", str(_free_port()))
    webrtc = () if request.node.get_closest_marker("no_webrtc") else ("--webrtc",)
    server = ServerProcess(tmp_path, ("--mcp", *video, *webrtc))
    try:
        with connect(server.url, max_size=None) as ws:
            robot = Robot(ws)
            try:
                yield server, robot
            finally:
                robot.close()
    finally:
        server.stop()


@pytest.fixture
def host_page(browser: Browser) -> Iterator[Page]:
    with serve_pages(lambda _path, _query: None, HOST_DIR) as site:
        page = browser.new_page()
        try:
            page.goto(f"{site}/host.html")
            page.wait_for("typeof window.showRobotApp === 'function'", 20, "the host's script")
            yield page
        finally:
            page.close()


def _mouse(page: Page, kind: str, x: float, y: float) -> None:
    page.send("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", clickCount=1)


def _show(server: ServerProcess, page: Page) -> tuple[str, dict[str, Any]]:
    """Have the host call ``robot_app`` and render its app: the app's URI, the host's state."""
    endpoint = server.url.replace("ws://", "http://") + "/mcp"
    show = f"showRobotApp({json.dumps({'endpoint': endpoint, 'token': None, 'args': ARGS})})"
    uri = page.evaluate(show)
    host = page.wait_for("window.host.initialized && window.host", 20, "the app's handshake")
    return uri, host


def _near(pixel: tuple[int, ...], rgb: tuple[int, int, int]) -> bool:
    return max(abs(a - b) for a, b in zip(pixel[:3], rgb, strict=True)) < 50


def test_a_host_renders_the_app_the_camera_shows_and_the_pad_drives_only_while_held(
    robot: tuple[ServerProcess, Robot], host_page: Page
) -> None:
    server, bot = robot
    uri, host = _show(server, host_page)
    assert uri == "ui://rwt/robot"  # the tool's _meta.ui names the app
    http = server.url.replace("ws://", "http://")
    settings = host["result"]["structuredContent"]
    assert settings["webrtc_url"] == f"{http}/webrtc?video=/camera/image"
    assert settings["teleop"] is True and settings["rate_hz"] == 5.0
    csp = host["meta"]["ui"]["csp"]
    assert csp["connectDomains"] == [http]  # what the frame may reach: the server, no more

    # the camera: the frame shows the robot's picture (WebRTC through the declared CSP)
    wait_until(lambda: _camera(host_page), 30, "the camera's picture in the app")
    assert "protocol=video" in server.stderr_path.read_text()  # a video-only WebRTC peer

    # the pad: held above its center (forward, no turn) for about a second, then let go
    frame = host_page.evaluate(
        "(({x, y}) => [x, y])(document.getElementById('app').getBoundingClientRect())"
    )
    x, y = frame[0] + PAD_X + PAD_SIZE / 2, frame[1] + PAD_Y + PAD_SIZE / 4
    _mouse(host_page, "mouseMoved", x, y)
    _mouse(host_page, "mousePressed", x, y)
    pressed = time.monotonic()
    time.sleep(1.2)
    _mouse(host_page, "mouseReleased", x, y)
    released = time.monotonic()
    wait_until(lambda: any(_stopped(msg) for _, msg in bot.twists), 10, "the zero Twist")
    time.sleep(1.0)  # nothing more comes once it is let go
    driving = [msg for at, msg in bot.twists if not _stopped(msg)]
    assert 3 <= len(driving) <= 9, bot.twists  # 5 a second while held
    for msg in driving:
        assert msg["linear"]["x"] == pytest.approx(0.25, abs=0.05)  # half way up: half speed
        assert msg["angular"]["z"] == pytest.approx(0.0, abs=0.15)  # a few pixels off
    assert all(pressed <= at for at, _ in bot.twists)
    last_drive = max(at for at, msg in bot.twists if not _stopped(msg))
    assert last_drive < released + 0.5  # none well after the release
    assert _stopped(bot.twists[-1][1]) and sum(_stopped(m) for _, m in bot.twists) == 1
    # held again, the host closes the app (its teardown) before the mouse lets go: the
    # app answers the teardown once it has stopped the robot, and drives no more
    count = len(bot.twists)
    _mouse(host_page, "mousePressed", x, y)
    wait_until(lambda: len(bot.twists) > count, 10, "driving again")
    assert host_page.evaluate("closeRobotApp()") is True
    closed = time.monotonic()
    wait_until(lambda: _stopped(bot.twists[-1][1]), 10, "the zero Twist of the teardown")
    time.sleep(1.0)
    assert _stopped(bot.twists[-1][1])
    assert not any(at > closed + 0.5 and not _stopped(msg) for at, msg in bot.twists)
    _mouse(host_page, "mouseReleased", x, y)


@pytest.mark.no_webrtc
def test_without_webrtc_the_app_shows_the_camera_as_mjpeg(
    robot: tuple[ServerProcess, Robot], host_page: Page
) -> None:
    _, host = _show(robot[0], host_page)
    settings = host["result"]["structuredContent"]
    assert settings["webrtc_url"] is None and "/stream?topic=/camera/image" in settings["mjpeg_url"]
    wait_until(lambda: _camera(host_page), 30, "the camera's MJPEG picture in the app")


def _camera(page: Page) -> bool:
    """Whether the app shows the camera: red at the left of its picture, blue at the right."""
    shot = Image.open(io.BytesIO(page.screenshot("#app"))).convert("RGB")
    return _near(shot.getpixel((10 + 80, 10 + 60)), RED) and _near(
        shot.getpixel((10 + 240, 10 + 60)), BLUE
    )


def _stopped(msg: dict[str, Any]) -> bool:
    return msg["linear"]["x"] == 0 and msg["angular"]["z"] == 0
