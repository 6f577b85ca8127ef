"""The console in headless Chromium against `rwt serve --video`, with a roslibpy robot.

One browser and one server for the module; the scenarios run in order on one
page, as a user would click through it (docs/console.md).
"""

from __future__ import annotations

import io
import json
import time
from collections.abc import Iterator

import numpy as np
import pytest
from PIL import Image

from .cdp import Browser, Page, wait_until
from .conftest import RobotProcess
from .robot import BLUE, RED

TOPIC_ROW = '#topics tbody tr[data-name="{}"]'


@pytest.fixture(scope="module")
def page(browser: Browser, video_server: tuple[str, str], robot: RobotProcess) -> Iterator[Page]:
    ws_url, _ = video_server
    page = browser.new_page()
    page.goto(ws_url.replace("ws://", "http://") + "/")
    page.wait_for("!!document.querySelector('#status.ok')", what="the console to connect")
    yield page
    page.close()


def test_loads_without_console_errors(page: Page) -> None:
    assert page.text("#status") == "connected"
    page.wait_for(f"!!document.querySelector('{TOPIC_ROW.format('/client_count')}')")
    assert page.errors() == []


def test_all_assets_come_from_the_server(page: Page, video_server: tuple[str, str]) -> None:
    """Chromium resolves no other host: the page loaded, so nothing came from elsewhere."""
    ws_url, _ = video_server
    origin = ws_url.removeprefix("ws://")
    urls = page.requested_urls()
    assert any(url.endswith("/console/main.js") for url in urls)
    assert any(url.startswith("ws://") for url in urls)
    assert all(url.split("://", 1)[1].startswith(origin) for url in urls), urls


def test_lists_a_topic_published_from_python(page: Page) -> None:
    row = TOPIC_ROW.format("/console_test/chatter")
    page.wait_for(f"!!document.querySelector('{row}')", what="the chatter topic")
    cells = page.evaluate(f"[...document.querySelector('{row}').cells].map(c => c.textContent)")
    assert cells[:3] == ["/console_test/chatter", "std_msgs/msg/String", "1"]
    services = page.evaluate(
        "[...document.querySelectorAll('#services li')].map(l => l.textContent)"
    )
    assert "/console_test/add" in services
    assert "/rosapi/topics" in services


def test_echoes_a_topic(page: Page) -> None:
    page.click(TOPIC_ROW.format("/console_test/chatter"))
    text = page.wait_for(
        "(t => /hello \\d+/.test(t) && t)(document.querySelector('#echo-output').textContent)",
        what="a chatter message in the echo",
    )
    assert '"hello' in text
    page.wait_for("/[1-9][0-9.]* Hz/.test(document.querySelector('#echo-stats').textContent)")
    row = TOPIC_ROW.format("/console_test/chatter")
    rate = page.wait_for(f"Number(document.querySelector('{row} .hz').textContent)")
    assert rate > 1  # about 10 Hz, measured in the page
    assert page.text(f"{row} .bw").endswith("B/s")


def test_echo_pauses_and_keeps_the_last_n(page: Page) -> None:
    page.fill("#echo-keep", "2")
    messages = "document.querySelectorAll('#echo-output .message')"
    page.wait_for(f"{messages}.length === 2", what="the echo to keep two messages")
    page.click("#echo-pause")
    assert page.text("#echo-pause") == "Resume"
    held = page.text("#echo-output")
    time.sleep(0.5)  # five more messages arrive meanwhile; none is shown
    assert page.text("#echo-output") == held
    page.click("#echo-pause")
    page.wait_for(f"document.querySelector('#echo-output').textContent !== {json.dumps(held)}")
    assert page.evaluate(f"{messages}.length") == 2


def test_echoes_a_latched_topic_the_page_already_watches(page: Page) -> None:
    """/client_count is latched, and the page subscribed to it first: the echo still shows it."""
    page.click(TOPIC_ROW.format("/client_count"))
    text = page.wait_for(
        "(t => /data: [0-9]+/.test(t) && t)(document.querySelector('#echo-output').textContent)",
        what="the latched client count in the echo",
    )
    assert int(text.split("data: ")[1]) >= 2  # the robot and this page


def test_plots_numeric_fields(page: Page) -> None:
    page.click(TOPIC_ROW.format("/console_test/point"))
    checked = page.wait_for(
        "(b => b.length && b)([...document.querySelectorAll('#plot-fields input:checked')]"
        ".map(i => i.value))",
        what="the plotted fields",
    )
    assert checked == ["x", "y", "z"]  # three numbers or fewer are plotted at once

    def lines_drawn() -> bool:
        plot = Image.open(io.BytesIO(page.screenshot("#plot"))).convert("RGB")
        # below the legend row, where only the lines are
        area = plot.crop((0, plot.height // 5, plot.width, plot.height))
        rgb = np.asarray(area).astype(int)
        r, b = rgb[..., 0], rgb[..., 2]
        blue = int(((b > 150) & (r < 100)).sum())  # x: '#2b7bd6'
        red = int(((r > 150) & (b < 100)).sum())  # y: '#d6472b'
        return blue > 20 and red > 20  # lines across the plot, not a dot

    wait_until(lines_drawn, 10, "the x and y lines on the plot")


def test_publishes_from_the_form(page: Page, robot: RobotProcess) -> None:
    page.click(TOPIC_ROW.format("/console_test/command"))
    page.wait_for("!!document.querySelector('#publish-fields input[name=\"msg.data\"]')")
    page.fill('#publish-fields input[name="msg.data"]', "go forward")
    page.click("#publish")
    assert robot.next_command() == {"data": "go forward"}
    assert "published" in page.text("#publish-result")


def test_calls_a_service_provided_by_roslibpy(page: Page) -> None:
    page.click('#services li[data-name="/console_test/add"]')
    page.wait_for("!!document.querySelector('#service-fields input[name=\"req.b\"]')")
    page.fill('#service-fields input[name="req.a"]', "20")
    page.fill('#service-fields input[name="req.b"]', "22")
    page.click("#service-call")
    text = page.wait_for(
        "(t => t.includes('sum') && t)(document.querySelector('#service-result').textContent)"
    )
    assert "sum: 42" in text


def test_shows_an_image_topic(page: Page) -> None:
    page.click('#tabs button[data-tab="images"]')
    selector = '#images figure[data-topic="/camera/image"] img'
    page.wait_for(
        f"(i => i && i.naturalWidth > 0)(document.querySelector('{selector}'))",
        what="the MJPEG image",
    )
    shot = Image.open(io.BytesIO(page.screenshot(selector))).convert("RGB")
    width, height = shot.size
    left = shot.getpixel((width // 4, height // 2))
    right = shot.getpixel((3 * width // 4, height // 2))
    assert all(abs(a - b) < 40 for a, b in zip(left, RED, strict=True)), left
    assert all(abs(a - b) < 40 for a, b in zip(right, BLUE, strict=True)), right


def test_shows_an_image_topic_as_vp8(page: Page) -> None:
    """The console starts the muted VP8 <video> with play(): it plays on its own."""
    page.evaluate(
        "(s => { s.value = 'vp8'; s.dispatchEvent(new Event('change')); })"
        "(document.getElementById('image-kind'))"
    )
    playing(page, '#images figure[data-topic="/camera/noise"] video')
    assert page.evaluate(
        "document.querySelector('#images figure[data-topic=\"/camera/noise\"] button').hidden"
    )


def test_tf_tree_lists_frames(page: Page) -> None:
    page.click('#tabs button[data-tab="tf"]')
    path = page.wait_for(
        "(f => f && [...(function* (n) { while (n && n.dataset) {"
        " if (n.dataset.frame) yield n.dataset.frame; n = n.parentElement; } })(f)])"
        "(document.querySelector('#tf-tree li[data-frame=\"camera\"]'))",
        what="the camera frame in the TF tree",
    )
    assert path == ["camera", "base_link", "odom", "map"]
    assert page.evaluate("document.getElementById('tf-tree').childNodes.length") == 1  # no cycle


def test_server_tab_shows_connections(page: Page) -> None:
    page.click('#tabs button[data-tab="server"]')
    # the two topics are published apart: wait until both show the same state
    count = page.wait_for(
        "(n => n === document.querySelectorAll('#clients tbody tr').length && n)"
        "(Number(document.querySelector('#client-count').textContent))",
        what="the client count and the client list to agree",
    )
    assert count >= 2  # the robot and this page
    addresses = page.evaluate(
        "[...document.querySelectorAll('#clients tbody tr td:first-child')].map(c => c.textContent)"
    )
    assert all(address.startswith("127.0.0.1") for address in addresses), addresses
    limit = page.text('#limits tr[data-name="--max-message-size"] td:last-child')
    assert limit == str(10 * 1024 * 1024)
    assert page.errors() == []


def test_no_errors_after_the_tour(page: Page) -> None:
    assert page.errors() == [], json.dumps(page.errors())


def playing(page: Page, selector: str) -> None:
    """Wait until the <video> has data to play (readyState >= 3) and its time advances."""
    video = f"document.querySelector({json.dumps(selector)})"
    page.wait_for(f"(v => v && v.readyState >= 3)({video})", 20, f"{selector} to have data")
    start = page.evaluate(f"{video}.currentTime")
    page.wait_for(f"{video}.currentTime > {start} + 0.2", 20, f"{selector} to play")
    assert not page.evaluate(f"{video}.paused")


@pytest.mark.parametrize("kind", ["vp8", "h264"])
def test_the_video_viewer_plays(
    browser: Browser, video_server: tuple[str, str], robot: RobotProcess, kind: str
) -> None:
    """web_video_server's viewer page under Chromium's default autoplay policy."""
    _, video_url = video_server
    viewer = browser.new_page()
    try:
        if kind == "h264":
            mp4 = 'video/mp4; codecs="avc1.42E01E"'
            if not viewer.evaluate(f"document.createElement('video').canPlayType({mp4!r})"):
                pytest.skip("this Chromium has no H.264 decoder")
        # noise: a small still image makes too few bytes a second for Chromium to start
        viewer.goto(f"{video_url}/stream_viewer?topic=/camera/noise&type={kind}")
        playing(viewer, "video")
        assert viewer.evaluate("document.getElementById('play').hidden")
        assert viewer.errors() == []
    finally:
        viewer.close()


def test_the_console_from_the_video_port(browser: Browser, video_server: tuple[str, str]) -> None:
    """Served by the video server, the page finds the WebSocket through config.json."""
    ws_url, video_url = video_server
    console = browser.new_page()
    try:
        console.goto(f"{video_url}/console/")
        console.wait_for("!!document.querySelector('#status.ok')", what="the console to connect")
        assert console.text("#server-url") == ws_url + "/"
        console.wait_for(f"!!document.querySelector('{TOPIC_ROW.format('/camera/image')}')")
        assert console.errors() == []
    finally:
        console.close()
