"""Chromium under the envelope: roslib over a WebRTC data channel, and the console.

``rwt serve --webrtc --safety FILE`` with the example's rules. A page running roslib
over the rosbridge data channel (the transport of docs/webrtc.md) publishes a Twist
out of bounds and gets it back clamped on its own subscription, then the dead-man's
stop once it goes quiet; a joint command out of bounds never comes back, the next one
does. The web console's Server tab shows the rules and the last events (a clamp of
another client's), from ``/rwt/safety`` (docs/safety.md, docs/console.md).
"""

from __future__ import annotations

import json
import urllib.parse
from collections.abc import Iterator
from pathlib import Path

import pytest
from websockets.sync.client import connect

from tests.browser.cdp import Browser
from tests.integration.client_harness import ServerProcess
from tests.safety.example import example_file, twist
from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from tests.webrtc.pagesite import MODULES, serve_pages
from tests.webrtc.test_browser import DOCUMENTED_SERVER, IMPORTS, documented_page

PAGE_TEST = """
ros.on("error", (e) => { window.failure = String(e && (e.message || e.type || e)); });
ros.on("connection", async () => {
  try {
    const drive = new Topic({ ros, name: "/cmd_vel", messageType: "geometry_msgs/Twist" });
    const joint = new Topic({ ros, name: "/arm/joint_cmd", messageType: "std_msgs/Float64" });
    const twists = [];
    const joints = [];
    const stopped = new Promise((ok) => drive.subscribe((m) => {
      twists.push([m.linear.x, m.angular.z]);
      if (twists.length === 2) ok();
    }));
    const moved = new Promise((ok) => joint.subscribe((m) => { joints.push(m.data); ok(); }));
    await new Promise((ok) => setTimeout(ok, 300));  // the subscriptions reach the server
    drive.publish(%(drive)s);  // then quiet: the dead-man stops it
    joint.publish({ data: 9.0 });
    joint.publish({ data: 1.0 });
    await moved;
    await stopped;
    window.result = { twists, joints };
  } catch (e) { window.failure = String(e); }
});
"""


def _page(server: str) -> str:
    imports = {name: f"/node_modules/{path}" for name, path in IMPORTS.items()}
    script = documented_page().replace(DOCUMENTED_SERVER, server)
    test = PAGE_TEST % {"drive": json.dumps(twist(2.0, -5.0))}
    return (
        "<!doctype html><html><head>"
        f'<script type="importmap">{json.dumps({"imports": imports})}</script>'
        f'<script type="module">{script}{test}</script>'
        "</head><body>roslib over WebRTC under the envelope</body></html>"
    )


@pytest.fixture(scope="module")
def site() -> Iterator[str]:
    if not (MODULES / "roslib").is_dir():
        pytest.skip("roslib is not installed: npm ci --prefix tests/js")

    def page(path: str, query: str) -> str | None:
        return _page(urllib.parse.parse_qs(query)["server"][0]) if path == "/" else None

    with serve_pages(page) as url:
        yield url


def test_roslib_over_webrtc_is_held_to_the_bounds(
    browser: Browser, site: str, tmp_path: Path
) -> None:
    rules = example_file(tmp_path)
    server = ServerProcess(tmp_path, ("--webrtc", "--safety", str(rules)))
    try:
        page = browser.new_page()
        try:
            page.goto(f"{site}/?server={server.url.replace('ws://', 'http://')}")
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
    assert result["twists"] == [[0.5, -1.0], [0.0, 0.0]]  # clamped, then the dead-man's stop
    assert result["joints"] == [1.0]  # 9.0 was refused: nothing delivered
    log = server.stderr_path.read_text()
    assert "event=safety_clamp client=webrtc:" in log
    assert "event=safety_reject client=webrtc:" in log


def test_the_console_shows_the_envelope_and_the_last_events(
    browser: Browser, tmp_path: Path
) -> None:
    rules = example_file(tmp_path)
    server = ServerProcess(tmp_path, ("--safety", str(rules)))
    try:
        with connect(server.url) as ws:  # another client drives too fast
            publish = {"op": "publish", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist"}
            ws.send(json.dumps({**publish, "msg": twist(2.0)}))
            ws.send(json.dumps({"op": "call_service", "service": "/rosapi/get_time", "id": "t"}))
            while '"service_response"' not in str(ws.recv(timeout=20)):
                pass
        page = browser.new_page()
        try:
            page.goto(server.url.replace("ws://", "http://") + "/")
            page.wait_for("!!document.querySelector('#status.ok')", 30, "the console")
            page.click('button[data-tab="server"]')
            page.wait_for(
                "!!document.querySelector('#safety-events tr[data-kind=\"deadman_stop\"]')",
                30,
                "the envelope's events",
            )
            rules_shown = page.evaluate(
                "[...document.querySelectorAll('#safety-rules tbody tr')]"
                ".map(r => [...r.cells].map(c => c.textContent))"
            )
            events = page.evaluate(
                "[...document.querySelectorAll('#safety-events tbody tr')]"
                ".map(r => [...r.cells].map(c => c.textContent))"
            )
            visible = page.evaluate("!document.getElementById('safety').hidden")
            errors = page.errors()
        finally:
            page.close()
    finally:
        server.stop()
    assert visible
    assert rules_shown[0][:4] == [
        "/cmd_vel",
        "geometry_msgs/msg/Twist",
        "linear.x [-0.5, 0.5], angular.z [-1, 1]",
        "clamp",
    ]
    assert rules_shown[0][5:] == ["0.5 s", "yes"]
    joint = ["/arm/joint_cmd", "std_msgs/msg/Float64", "data [0, 3.14]", "reject"]
    assert rules_shown[1][:4] == joint
    kinds = [row[1] for row in events]
    assert kinds == ["deadman_stop", "clamp"]  # the newest first
    assert events[1][3:6] == ["/cmd_vel", "linear.x", "2"]
    assert errors == []
