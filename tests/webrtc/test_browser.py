"""Chromium running roslib 2.x over the data channels: the page of docs/webrtc.md.

The page's code is the one docs/webrtc.md shows (read from the page itself, with
the server's address), which imports the transport factory rwt serves at
``/webrtc/roslib-transport.js``; the page comes from another origin than
``rwt serve --webrtc`` (so CORS is the browser's), with roslib and its
dependencies from tests/js/node_modules.
"""

from __future__ import annotations

import json
import urllib.parse
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from tests.browser.cdp import Browser
from tests.integration.client_harness import ServerProcess
from tests.webrtc.pagesite import MODULES, serve_pages

REPO = Path(__file__).resolve().parents[2]

IMPORTS = {
    "roslib": "roslib/dist/RosLib.js",
    "eventemitter3": "eventemitter3/dist/eventemitter3.esm.js",  # its ESM build
    "uuid": "uuid/dist/index.js",
    "bson": "bson/lib/bson.mjs",
    "cbor2": "cbor2/lib/index.js",
    "fast-png": "fast-png/lib/index.js",
    "fflate": "fflate/esm/browser.js",
    "iobuffer": "iobuffer/lib/iobuffer.js",
    "@cto.af/wtf8": "@cto.af/wtf8/lib/index.js",
}
"""roslib and what it imports, as an import map over tests/js/node_modules (no network)."""

BIG = 100_000
"""Characters of the message that must come back in ``fragment`` ops (over 64 KiB)."""


DOCUMENTED_SERVER = "http://127.0.0.1:9090"
"""The server's address in the page of docs/webrtc.md; the test puts its own in."""


def documented_page() -> str:
    """The JavaScript of docs/webrtc.md's page with roslib: the factory's import and ``ros``."""
    page = (REPO / "docs" / "webrtc.md").read_text("utf-8")
    block = next(b for b in page.split("```text\n")[1:] if "transportFactory" in b)
    return block.split("```", 1)[0]


PAGE_TEST = """
ros.on("error", (e) => { window.failure = String(e && (e.message || e.type || e)); });
ros.on("connection", async () => {
  try {
    const topics = await new Promise((ok, fail) => new Service({
      ros, name: "/rosapi/topics", serviceType: "rosapi/Topics",
    }).callService({}, ok, fail));
    const echo = new Topic({ ros, name: "/page_echo", messageType: "std_msgs/String" });
    const big = "x".repeat(%(big)d) + "\\u00e9";
    const received = new Promise((ok) => echo.subscribe((m) => ok(m.data)));
    await new Promise((ok) => setTimeout(ok, 200));  // the subscription reaches the server
    echo.publish({ data: big });
    const back = await received;
    const pose = new Topic({ ros, name: "/pose", messageType: "geometry_msgs/Pose" });
    const fast = new Promise((ok) => pose.subscribe((m) => ok(m.position.x)));  // lossy
    await new Promise((ok) => setTimeout(ok, 200));
    pose.publish({ position: { x: 1.5, y: 0, z: 0 }, orientation: { x: 0, y: 0, z: 0, w: 1 } });
    const x = await fast;
    window.result = { topics: topics.topics, same: back === big, length: back.length, x };
  } catch (e) { window.failure = String(e); }
});
"""


def page_html(server: str) -> str:
    """The page, its code the documented one with ``server`` for the documented address."""
    imports = {name: f"/node_modules/{path}" for name, path in IMPORTS.items()}
    script = documented_page().replace(
        'import { Ros, Topic, AbstractTransport } from "roslib";',
        'import { Ros, Topic, Service, AbstractTransport } from "roslib";',
    )
    assert DOCUMENTED_SERVER in script
    script = script.replace(DOCUMENTED_SERVER, server)
    return (
        "<!doctype html><html><head>"
        f'<script type="importmap">{json.dumps({"imports": imports})}</script>'
        f'<script type="module">{script}{PAGE_TEST % {"big": BIG}}</script>'
        "</head><body>roslib over WebRTC</body></html>"
    )


def _page(path: str, query: str) -> str | None:
    """The page at ``/?server=URL``."""
    if path != "/":
        return None
    return page_html(urllib.parse.parse_qs(query)["server"][0])


@pytest.fixture(scope="module")
def site() -> Iterator[str]:
    if not (MODULES / "roslib").is_dir():
        pytest.skip("roslib is not installed: npm ci --prefix tests/js")
    with serve_pages(_page) as url:
        yield url


def test_roslib_in_chromium_talks_rosbridge_over_the_data_channel(
    browser: Browser, site: str, tmp_path: Path, stack: str
) -> None:
    server = ServerProcess(tmp_path, ("--webrtc", "--webrtc-stack", stack))
    try:
        http_url = server.url.replace("ws://", "http://")
        page = browser.new_page()
        try:
            page.goto(f"{site}/?server={http_url}")
            result = page.wait_for(
                "window.result || (window.failure && {failure: window.failure})",
                30,
                "roslib over WebRTC",
            )
        finally:
            page.close()
    finally:
        server.stop()
    assert "failure" not in result, result
    assert "/client_count" in result["topics"]
    assert result["same"] is True and result["length"] == BIG + 1
    assert result["x"] == 1.5  # received on the lossy channel
    log = server.stderr_path.read_text()
    assert "transport=webrtc" in log  # the session was the data channel's, not a WebSocket
    assert "event=lossy_channel" in log  # and the page opened the lossy one beside it


def test_the_console_talks_over_the_data_channel_with_webrtc_in_its_url(
    browser: Browser, tmp_path: Path, stack: str
) -> None:
    server = ServerProcess(tmp_path, ("--webrtc", "--webrtc-stack", stack))
    try:
        page = browser.new_page()
        try:
            page.goto(server.url.replace("ws://", "http://") + "/?webrtc")
            page.wait_for("!!document.querySelector('#status.ok')", 30, "the console to connect")
            page.wait_for(
                "!!document.querySelector('#topics tbody tr[data-name=\"/client_count\"]')",
                30,
                "the graph over the data channel",
            )
            shown = page.text("#server-url")
            requested = page.requested_urls()
            errors = page.errors()
        finally:
            page.close()
    finally:
        server.stop()
    assert shown.endswith("/webrtc (WebRTC)")
    assert not any(url.startswith("ws://") for url in requested)  # no WebSocket at all
    assert errors == []
    log = server.stderr_path.read_text()
    assert "transport=webrtc" in log and "transport=ws" not in log
