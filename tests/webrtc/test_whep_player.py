"""A real WHEP player in Chromium plays an image topic: ``@eyevinn/webrtc-player`` (docs/webrtc.md).

The player, as published on npm, is pointed at ``/webrtc?video=/camera/image`` of a
server with a camera (camera_robot.py) and fills a ``<video>`` element: it must get
the camera's size, play (its time advances), and show the camera's colours. The
player's CommonJS build is loaded by a small ``require`` over tests/js/node_modules
(no bundler, no network); the page is served from another origin than the server.
A second page offers H.264 only (``setCodecPreferences``), so Chromium's own decoder
plays the libx264 stream.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.webrtc.conftest import NEEDS_AIORTC, video_stack

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from tests.browser.cdp import Browser
from tests.integration.client_harness import ServerProcess
from tests.webrtc.camera_robot import BLUE, RED
from tests.webrtc.pagesite import MODULES, serve_pages

PLAYER = "@eyevinn/webrtc-player"

REQUIRE = """
window.process = { env: { NODE_ENV: "production" } };
window.global = window;
const loaded = {};
const isJs = (p) => /\\.[cm]?js$/.test(p);
function get(path) {
  const request = new XMLHttpRequest();
  request.open("GET", path, false);  // require() is synchronous
  request.send();
  return request.status === 200 ? request.responseText : null;
}
function packageRoot(path) {  // "/node_modules/@a/b/dist/x.js" -> "/node_modules/@a/b/"
  const at = path.lastIndexOf("/node_modules/");
  if (at < 0) return null;
  const parts = path.slice(at + 14).split("/");
  return path.slice(0, at + 14) + parts.slice(0, parts[0].startsWith("@") ? 2 : 1).join("/") + "/";
}
function resolve(name, from) {
  if (name.startsWith(".")) {
    const path = new URL(name, location.origin + from).pathname;
    return isJs(path) ? path : path + ".js";
  }
  const parts = name.split("/");
  const n = name.startsWith("@") ? 2 : 1;
  const pkg = parts.slice(0, n).join("/"), sub = parts.slice(n).join("/");
  const root = packageRoot(from);
  let base = "/node_modules/" + pkg + "/";  // a nested copy first, as Node looks
  if (root && get(root + "node_modules/" + pkg + "/package.json") !== null) {
    base = root + "node_modules/" + pkg + "/";
  }
  if (sub) return base + sub + (isJs(sub) ? "" : ".js");
  // a browser build first, as bundlers do, unless it is an ES module (require needs CommonJS)
  const meta = JSON.parse(get(base + "package.json"));
  const browser = typeof meta.browser === "string" ? get(base + meta.browser) : null;
  const commonJs = browser !== null && !/(^|[;}\\n])\\s*export[\\s{]/.test(browser);
  const entry = commonJs ? meta.browser : meta.main;
  const main = (entry || "index.js").replace(/^\\.\\//, "");
  if (isJs(main)) return base + main;
  return get(base + main + ".js") !== null ? base + main + ".js" : base + main + "/index.js";
}
function load(path) {
  if (!loaded[path]) {
    const module = (loaded[path] = { exports: {} });
    const code = get(path) + "\\n//# sourceURL=" + path;
    new Function("module", "exports", "require", code)(
      module, module.exports, (name) => load(resolve(name, path)));
  }
  return loaded[path].exports;
}
"""

PLAY = """
const { WebRTCPlayer } = load(resolve("%(player)s", "/"));
const server = new URL(location.href).searchParams.get("server");
const video = document.getElementById("video");
const player = new WebRTCPlayer({ video, type: "whep" });
player.load(new URL(server + "/webrtc?video=/camera/image"))
  .catch((e) => { window.failure = String(e); });
"""


SAMPLE = """
window.sample = () => {  // the size, the time, and the colours left and right
  const video = document.getElementById("video");
  const canvas = document.createElement("canvas");
  canvas.width = video.videoWidth; canvas.height = video.videoHeight;
  const context = canvas.getContext("2d");
  context.drawImage(video, 0, 0);
  const at = (x) => Array.from(context.getImageData(x, canvas.height / 2, 1, 1).data.slice(0, 3));
  return { width: video.videoWidth, height: video.videoHeight, time: video.currentTime,
           left: at(canvas.width / 8), right: at(canvas.width * 7 / 8),
           // 20 px on: the camera's 8 px white bar covers at most one of each pair
           left2: at(canvas.width / 8 + 20), right2: at(canvas.width * 7 / 8 - 20) };
};
"""

H264 = """
const server = new URL(location.href).searchParams.get("server");
(async () => {
  const pc = new RTCPeerConnection();
  const transceiver = pc.addTransceiver("video", { direction: "recvonly" });
  const h264 = RTCRtpReceiver.getCapabilities("video").codecs
    .filter((c) => c.mimeType === "video/H264");
  if (!h264.length) { window.failure = "no H.264 in this Chromium"; return; }
  transceiver.setCodecPreferences(h264);
  pc.ontrack = (e) => { document.getElementById("video").srcObject = e.streams[0]; };
  await pc.setLocalDescription(await pc.createOffer());
  await new Promise((done) => {
    if (pc.iceGatheringState === "complete") return done();
    pc.onicegatheringstatechange = () => pc.iceGatheringState === "complete" && done();
  });
  const reply = await fetch(server + "/webrtc?video=/camera/image", {
    method: "POST", headers: { "Content-Type": "application/sdp" }, body: pc.localDescription.sdp,
  });
  if (reply.status !== 201) { window.failure = await reply.text(); return; }
  const answer = await reply.text();
  window.codec = (answer.match(/a=rtpmap:\\d+ (\\w+)\\/90000/) || [])[1];
  window.answerer = (answer.match(/\\no=(\\S+)/) || [])[1];  // "rtc": libdatachannel
  await pc.setRemoteDescription({ type: "answer", sdp: answer });
})().catch((e) => { window.failure = String(e); });
"""


def page_html(path: str = "/") -> str:
    script = H264 if path == "/h264" else REQUIRE + PLAY % {"player": PLAYER}
    return (
        "<!doctype html><html><body>"
        '<video id="video" muted autoplay playsinline></video>'
        f"<script>{SAMPLE}{script}</script>"
        "</body></html>"
    )


@pytest.fixture
def site() -> Iterator[str]:
    if not (MODULES / PLAYER).is_dir():
        pytest.skip(f"{PLAYER} is not installed: npm ci --prefix tests/js")
    with serve_pages(
        lambda path, _query: page_html(path) if path in ("/", "/h264") else None
    ) as url:
        yield url


def _near(pixel: list[int], rgb: tuple[int, int, int]) -> bool:
    return max(abs(a - b) for a, b in zip(pixel, rgb, strict=True)) < 40


def _coloured(sample: dict[str, Any]) -> bool:
    """Red on the left, blue on the right (one of each pair of points: the white bar moves)."""
    left = _near(sample["left"], RED) or _near(sample["left2"], RED)
    return left and (_near(sample["right"], BLUE) or _near(sample["right2"], BLUE))


def _watch(
    browser: Browser, site: str, tmp_path: Path, path: str, stack: str = "aiortc"
) -> tuple[Any, Any, str]:
    """Open ``path`` against a camera server on ``stack``: two samples playing, the log."""
    script = Path(__file__).with_name("camera_robot.py")
    server = ServerProcess(tmp_path, cmd=[sys.executable, str(script), stack])
    try:
        http_url = server.url.replace("ws://", "http://")
        page = browser.new_page()
        try:
            page.goto(f"{site}{path}?server={http_url}")
            failed = "window.failure ? {failure: window.failure} : window.sample && "
            first = page.wait_for(
                failed + "(sample().width > 0 && sample().time > 0 && sample())",
                40,
                "the player showing the camera",
            )
            assert "failure" not in first, (first, page.errors())
            later = page.wait_for(
                f"window.sample().time > {first['time']} && window.sample()", 20, "playing on"
            )
            later["codec"] = page.evaluate("window.codec || null")
            later["answerer"] = page.evaluate("window.answerer || null")
        finally:
            page.close()
    finally:
        server.stop()
    return first, later, server.stderr_path.read_text()


def test_a_whep_player_in_chromium_plays_the_camera(
    browser: Browser, site: str, tmp_path: Path, stack: str
) -> None:
    """On the native stack too: its offer (VP8 first, video only) goes to libdatachannel."""
    first, later, log = _watch(browser, site, tmp_path, "/", stack)
    assert (first["width"], first["height"]) == (320, 240)
    assert later["time"] > first["time"]  # it plays: the element's time advances
    assert _coloured(later), later
    assert "protocol=video peer=" in log  # a video-only WebRTC peer
    assert f"stack={video_stack(stack)}" in log, log


def test_chromium_preferring_h264_gets_h264(
    browser: Browser, site: str, tmp_path: Path, stack: str
) -> None:
    """On the native stack libdatachannel sends the H.264 track (D51)."""
    first, later, _ = _watch(browser, site, tmp_path, "/h264", stack)
    assert later["codec"] == "H264"  # the offer's preference decided
    assert (later["answerer"] == "rtc") == (video_stack(stack) == "native"), later
    assert (first["width"], first["height"]) == (320, 240)
    assert later["time"] > first["time"]
    assert _coloured(later), later
