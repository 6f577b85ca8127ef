"""The real Lichtblick web app, in headless Chromium, opening examples/robot.py.

No registry carries a built Lichtblick, so this runs only when ``RWT_LICHTBLICK_APP``
names a built web app (the folder with its ``index.html``: ``web/.webpack`` of a
``yarn web:build:prod`` of Lichtblick's source; CONTRIBUTING.md), and skips otherwise.
The app connects at once by its URL (``?ds=foxglove-websocket&ds.url=...``); the test
reads what a user sees: the topics listed, the alerts tab's count and the error icon
beside the connection's name. tests/foxglove/test_lichtblick_schemas.py replays the
same schema rule without the app.
"""

from __future__ import annotations

import functools
import http.server
import json
import os
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import quote

import pytest

from tests.integration.client_harness import REPO, ServerProcess

from .cdp import Browser, Page

APP_ENV = "RWT_LICHTBLICK_APP"
CONNECT_TIMEOUT_S = 120.0  # the app is 170 MB of scripts, on a shared machine

#: A robot whose sensor_msgs/msg/NavSatFix is Kilted's, which Lichtblick's Humble copy of
#: NavSatStatus lacks two constants of (docs/foxglove.md): the alert the test must see.
NAVSAT_ROBOT = """
import asyncio, sys
from rwt import Graph, RosbridgeServer, ServerConfig
graph = Graph()
graph.create_publisher("/fix", "sensor_msgs/msg/NavSatFix", latch=True)
server = RosbridgeServer(graph, ServerConfig(port=0))
asyncio.run(server.serve(on_listening=lambda url: print("listening on", url, flush=True)))
"""

# The text of the sidebar tab named TEXT after clicking it (buttons and tabs alike).
CLICK = """(text => {
  const hits = [...document.querySelectorAll('button, [role=tab]')]
    .filter((e) => e.innerText.trim().startsWith(text));
  hits.forEach((e) => e.click());
  return hits.map((e) => e.innerText);
})(%s)"""


@pytest.fixture(scope="module")
def app_url() -> Iterator[str]:
    folder = os.environ.get(APP_ENV)
    if not folder:
        pytest.skip(f"{APP_ENV} is not set: it names a built Lichtblick web app (CONTRIBUTING.md)")
    if not (Path(folder) / "index.html").is_file():
        pytest.fail(f"{APP_ENV}={folder} has no index.html")
    handler = functools.partial(QuietHandler, directory=folder)
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture
def robot(tmp_path: Path) -> Iterator[ServerProcess]:
    server = ServerProcess(tmp_path, cmd=[sys.executable, str(REPO / "examples" / "robot.py"), "0"])
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def navsat_robot(tmp_path: Path) -> Iterator[ServerProcess]:
    server = ServerProcess(tmp_path, cmd=[sys.executable, "-c", NAVSAT_ROBOT])
    try:
        yield server
    finally:
        server.stop()


def open_app(browser: Browser, app_url: str, ws_url: str, topic: str) -> Page:
    """The app connected to ``ws_url``, its topic list showing ``topic``."""
    page = browser.new_page()
    page.goto(f"{app_url}/?ds=foxglove-websocket&ds.url={quote(ws_url)}&openIn=web", 90)
    page.evaluate(CLICK % json.dumps("Topics"))
    page.wait_for(
        f"document.body.innerText.includes({json.dumps(topic)})",
        CONNECT_TIMEOUT_S,
        f"Lichtblick to list {topic}",
    )
    return page


def alerts(page: Page) -> tuple[int, str, int]:
    """The alerts tab's count, its list's text and the error icons beside the source."""
    [label] = page.evaluate(CLICK % json.dumps("Alerts"))
    page.wait_for("document.body.innerText.includes('Layouts')", 10, "the alerts tab")
    count = int("".join(ch for ch in label if ch.isdigit()) or 0)
    listing = page.evaluate("document.body.innerText")
    icons = page.evaluate("document.querySelectorAll('[class*=adornmentError] button').length")
    return count, listing, icons


def test_lichtblick_opens_the_example_robot_without_an_alert(
    browser: Browser, app_url: str, robot: ServerProcess
) -> None:
    page = open_app(browser, app_url, robot.url, "/velocity")
    try:
        text = page.evaluate("document.body.innerText")
        assert "geometry_msgs/msg/Twist" in text and "/fibonacci/_action/status" in text
        count, listing, icons = alerts(page)
        assert (count, icons) == (0, 0), listing
        assert "No alerts found" in listing
        assert page.errors() == []
    finally:
        page.close()


def test_lichtblick_flags_a_type_changed_since_humble(
    browser: Browser, app_url: str, navsat_robot: ServerProcess
) -> None:
    # the control: the same reading sees the alert Lichtblick raises
    page = open_app(browser, app_url, navsat_robot.url, "/fix")
    try:
        page.wait_for(
            "document.querySelectorAll('[class*=adornmentError] button').length > 0",
            30,
            "the error icon",
        )
        count, listing, icons = alerts(page)
        assert (count, icons) == (1, 1), listing
        assert "Definition of schema 'sensor_msgs/NavSatStatus' has changed" in listing
    finally:
        page.close()
