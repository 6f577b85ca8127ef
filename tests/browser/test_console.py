"""The console in headless Chromium against `rwt serve --video`, with a roslibpy robot.

One browser and one server for the module; the scenarios run in order on one
page, as a user would click through it (docs/console.md).
"""

from __future__ import annotations

import io
import json
import re
import time
from collections.abc import Iterator

import numpy as np
import pytest
from PIL import Image

from .cdp import Browser, Page, wait_until
from .conftest import RobotProcess
from .robot import BLUE, RED

TOPIC_ROW = '#topics tbody tr[data-name="{}"]'

# Two whole refreshes of the graph, by its Refresh button (the same refresh the 2 s
# timer runs). A refresh starts only once the one before has ended, and each starts
# with its /rosapi/topics call: the third start seen means two whole refreshes.
TWO_REFRESHES = """(async () => {
  let starts = 0;
  const send = WebSocket.prototype.send;
  WebSocket.prototype.send = function (data) {
    if (String(data).includes('"/rosapi/topics"')) starts += 1;
    return send.call(this, data);
  };
  try {
    for (let i = 0; starts < 3 && i < 300; i++) {
      document.getElementById('refresh').click();
      await new Promise((resolve) => setTimeout(resolve, 50));
    }
  } finally {
    WebSocket.prototype.send = send;
  }
  return starts;
})()"""


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
    details = page.wait_for(
        "(t => /window [1-9]/.test(t) && t)(document.getElementById('echo-details').textContent)",
        what="ros2 topic hz's figures",
    )
    # about 10 Hz: intervals near 0.1 s (two can arrive in one read of a loaded
    # machine's socket: a minimum of 0); the window's messages and their sizes
    gaps = [float(x) for x in re.findall(r"(?:min|max) ([0-9.]+)s", details)]
    assert len(gaps) == 2
    assert 0 <= gaps[0] <= gaps[1] < 2
    assert gaps[1] > 0.01
    assert "std dev" in details
    assert re.search(r"mean [1-9][0-9]* B min [1-9][0-9]* B max [1-9][0-9]* B", details)
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


def test_calls_a_set_bool_service_with_a_checkbox(page: Page) -> None:
    """rosapi names ROS 2's bool 'boolean': the form still offers a checkbox and sends true."""
    page.click('#services li[data-name="/console_test/lights"]')
    box = '#service-fields input[name="req.data"]'
    page.wait_for(f"!!document.querySelector('{box}')", what="the SetBool form")
    assert page.evaluate(f"document.querySelector('{box}').type") == "checkbox"
    page.click(box)
    page.click("#service-call")
    text = page.wait_for(
        "(t => t.includes('message') && t)(document.querySelector('#service-result').textContent)",
        what="the SetBool response",
    )
    assert "lights on" in text
    assert "success: true" in text


def test_a_refused_publish_shows_the_server_error_beside_the_button(page: Page) -> None:
    page.click(TOPIC_ROW.format("/console_test/level"))
    field = '#publish-fields input[name="msg.data"]'
    page.wait_for(f"!!document.querySelector('{field}')", what="the Int8 form")
    page.fill(field, "1000")  # an int8 holds -128..127
    page.click("#publish")
    text = page.wait_for(
        "(t => t.startsWith('refused') && t)"
        "(document.getElementById('publish-result').textContent)",
        what="the refusal beside Publish",
    )
    assert "1000" in text or "range" in text, text
    assert page.evaluate("document.getElementById('publish-result').className") == "error"
    page.fill(field, "100")
    page.click("#publish")
    page.wait_for(
        "document.getElementById('publish-result').textContent.startsWith('published')",
        what="a good publish after the refusal",
    )


def test_the_graph_is_chosen_with_the_keyboard_and_tabs_are_aria_tabs(page: Page) -> None:
    item = '#services li[data-name="/console_test/add"]'
    page.wait_for(f"!!document.querySelector('{item}')")
    assert page.evaluate(f"document.querySelector('{item}').tabIndex") == 0
    page.evaluate(f"document.querySelector('{item}').focus()")
    page.press("Enter", 13)
    page.wait_for(
        "document.getElementById('service-name').textContent === '/console_test/add'"
        " && !document.getElementById('tab-service').hidden",
        what="the service chosen with Enter",
    )
    assert page.evaluate("document.getElementById('tabs').getAttribute('role')") == "tablist"
    selected = page.evaluate(
        "[...document.querySelectorAll('#tabs [role=tab][aria-selected=true]')]"
        ".map(b => b.dataset.tab)"
    )
    assert selected == ["service"]
    page.evaluate("document.querySelector('#tabs [aria-selected=true]').focus()")
    page.press("ArrowRight", 39)
    page.wait_for("!document.getElementById('tab-action').hidden", what="the next tab")
    row = TOPIC_ROW.format("/console_test/chatter")
    page.evaluate(f"document.querySelector('{row}').focus()")
    page.press(" ", 32)
    page.wait_for(
        "document.getElementById('topic-name').textContent === '/console_test/chatter'",
        what="the topic chosen with Space",
    )


def test_rows_are_updated_in_place_not_rebuilt(page: Page) -> None:
    """A row pressed between two refreshes is the same row when released (no lost clicks)."""
    row = TOPIC_ROW.format("/console_test/chatter")
    page.evaluate(f"window.keptRow = document.querySelector('{row}')")
    page.evaluate("window.keptItem = document.querySelector('#services li')")
    assert page.evaluate(TWO_REFRESHES) >= 3
    assert page.evaluate(f"window.keptRow === document.querySelector('{row}')")
    assert page.evaluate("window.keptRow.isConnected && window.keptItem.isConnected")


def test_one_column_at_800_px_and_names_wrap_only_after_a_slash(page: Page) -> None:
    page.send(
        "Emulation.setDeviceMetricsOverride",
        width=800,
        height=600,
        deviceScaleFactor=1,
        mobile=False,
    )
    try:
        width = page.wait_for(
            "(a => a.left === document.querySelector('main').getBoundingClientRect().left"
            " && a.width)(document.querySelector('aside').getBoundingClientRect())",
            what="the graph above the views, in one column",
        )
        assert width > 700  # the whole width, not a squeezed column
        row = TOPIC_ROW.format("/console_test/chatter")
        # a break opportunity after each '/', none inside a part
        assert page.evaluate(f"document.querySelector('{row} td wbr') !== null")
        assert page.evaluate(f"document.querySelectorAll('{row} td:first-child wbr').length") == 2
        wrap = page.evaluate(f"getComputedStyle(document.querySelector('{row} td')).overflowWrap")
        assert wrap == "break-word"
        page.send(
            "Emulation.setDeviceMetricsOverride",
            width=1400,
            height=900,
            deviceScaleFactor=1,
            mobile=False,
        )
        page.wait_for(  # two columns on a wide window
            "document.querySelector('aside').getBoundingClientRect().left"
            " < document.querySelector('main').getBoundingClientRect().left",
            what="two columns at 1400 px",
        )
    finally:
        page.send("Emulation.clearDeviceMetricsOverride")


TABLE_BOX = (
    "(() => { const box = document.querySelector('#topics').parentElement;"
    " const aside = document.querySelector('aside').getBoundingClientRect();"
    " const cells = [...document.querySelectorAll('#topics th, #topics td')]"
    "   .map(c => c.getBoundingClientRect()).filter(r => r.width > 0);"
    " return {right: Math.max(...cells.map(r => r.right)), column: aside.right,"
    "   box: box.getBoundingClientRect().right, scrolls: box.scrollWidth > box.clientWidth,"
    "   overflow: getComputedStyle(box).overflowX}; })()"
)


@pytest.mark.parametrize("width", [1920, 1400, 1100])
def test_the_topic_table_is_never_cut_off_by_the_views(page: Page, width: int) -> None:
    """Every column of the topic table shows, bandwidth included; at 1400 px it fits."""
    page.send(
        "Emulation.setDeviceMetricsOverride",
        width=width,
        height=900,
        deviceScaleFactor=1,
        mobile=False,
    )
    try:
        page.wait_for(
            "document.querySelectorAll('#topics tbody tr').length >= 5"
            " && document.querySelector('aside').getBoundingClientRect().left"
            " < document.querySelector('main').getBoundingClientRect().left",
            what=f"two columns at {width} px",
        )
        assert page.evaluate(TWO_REFRESHES) >= 3  # rates and bandwidths filled in
        seen = page.evaluate(TABLE_BOX)
        assert seen["box"] <= seen["column"] + 1  # the table's box stays in its column
        if width >= 1400:  # the robot's longest type wraps after a '/': it fits
            assert seen["right"] <= seen["column"] and not seen["scrolls"], seen
        else:  # narrower, a part alone may be too wide: the box scrolls, nothing is hidden
            assert seen["right"] <= seen["box"] or seen["overflow"] == "auto", seen
    finally:
        page.send("Emulation.clearDeviceMetricsOverride")


def test_counts_are_not_asked_for_every_topic_at_every_refresh(page: Page) -> None:
    """Publisher counts cost a call per topic: every 20 s, not every 2 s (docs/console.md)."""
    topics = page.wait_for(
        "(n => n >= 5 && n)(document.querySelectorAll('#topics tbody tr').length)",
        what="the robot's topics",
    )
    page.evaluate(
        "window.countCalls = 0; const send = WebSocket.prototype.send;"
        " WebSocket.prototype.send = function (data) {"
        " if (String(data).includes('/rosapi/publishers')) window.countCalls += 1;"
        " return send.call(this, data); }"
    )
    assert page.evaluate(TWO_REFRESHES) >= 3
    calls = page.evaluate("window.countCalls")
    page.evaluate("delete window.countCalls")
    # two refreshes asking for every topic would be 2 * topics; now at most one
    # round of all (every 20 s) and the selected topic's at each refresh
    assert calls < 2 * topics


def test_the_graph_filter_hides_what_does_not_match(page: Page) -> None:
    visible_topics = (
        "[...document.querySelectorAll('#topics tbody tr')].filter(r => !r.hidden)"
        ".map(r => r.dataset.name)"
    )
    visible_services = (
        "[...document.querySelectorAll('#services li')].filter(l => !l.hidden)"
        ".map(l => l.dataset.name)"
    )
    page.fill("#graph-filter", "chatter")
    assert page.evaluate(visible_topics) == ["/console_test/chatter"]
    page.fill("#graph-filter", "/console_test/*")
    shown = page.evaluate(visible_topics)
    assert "/console_test/point" in shown
    assert all(name.startswith("/console_test/") for name in shown)
    services = page.evaluate(visible_services)
    assert "/console_test/add" in services
    assert "/rosapi/topics" not in services
    page.fill("#graph-filter", "")
    assert "/client_count" in page.evaluate(visible_topics)


def test_the_log_tab_shows_rosout_with_a_level_filter_and_a_search(page: Page) -> None:
    page.click('#tabs button[data-tab="log"]')
    shown = "[...document.querySelectorAll('#rosout-log li')].filter(l => !l.hidden)"
    page.wait_for(
        f"{shown}.some(l => l.textContent.includes('[warn] robot: battery low'))"
        f" && {shown}.some(l => l.textContent.includes('[info] robot: tick'))",
        what="rosout lines at info and warn",
    )
    page.evaluate(
        "(s => { s.value = 'warn'; s.dispatchEvent(new Event('input')); })"
        "(document.getElementById('log-level'))"
    )
    levels = page.evaluate(f"[...new Set({shown}.map(l => l.dataset.level))]")
    assert levels == ["warn"]
    page.evaluate(
        "(s => { s.value = 'info'; s.dispatchEvent(new Event('input')); })"
        "(document.getElementById('log-level'))"
    )
    page.fill("#log-search", "battery")
    texts = page.evaluate(f"{shown}.map(l => l.textContent)")
    assert texts
    assert all("battery low" in text for text in texts)
    page.fill("#log-search", "")


def test_teleop_sends_twists_while_a_key_is_held_and_a_stop_on_release(
    page: Page, robot: RobotProcess
) -> None:
    page.click('#tabs button[data-tab="teleop"]')
    page.evaluate("document.getElementById('teleop-pad').focus()")
    page.key("keyDown", "w", 87)
    time.sleep(0.5)  # held: about five Twists
    page.key("keyUp", "w", 87)
    twists = []
    while True:
        line = robot.next_command()
        if "cmd_vel" not in line:
            continue
        twists.append(line["cmd_vel"])
        if twists[-1]["linear"]["x"] == 0:
            break
    assert len(twists) >= 3  # repeated while held, then the stop
    assert all(t["linear"]["x"] == 0.5 and t["angular"]["z"] == 0 for t in twists[:-1])
    assert twists[-1]["linear"] == {"x": 0.0, "y": 0.0, "z": 0.0}
    assert page.text("#teleop-state") == "stopped"
    # the dead-man: a key held when the pad loses the focus stops too
    page.evaluate("document.getElementById('teleop-pad').focus()")
    page.key("keyDown", "d", 68)
    page.evaluate("document.getElementById('teleop-topic').focus()")
    while True:
        line = robot.next_command()
        if "cmd_vel" in line and line["cmd_vel"]["angular"]["z"] == 0:
            break
    assert page.text("#teleop-state") == "stopped"


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
    # how Foxglove and Lichtblick connect: the same URL, no token without --auth-secret-file
    assert page.evaluate("document.getElementById('foxglove-help').hidden") is False
    assert page.text("#foxglove-url") == page.text("#server-url")
    assert page.evaluate("document.getElementById('foxglove-token').hidden") is True
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
