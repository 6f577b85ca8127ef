"""Every tab of the console, whichever tabs it has: accessible (axe-core) and not blank.

The tabs are read from the page's tablist, so a panel added to index.html is
covered without touching this file. For each one:

- axe-core (npm, tests/js), injected over CDP, finds no serious or critical
  violation (WCAG 2.x A/AA and best practices);
- what the window shows of its panel, the page scrolled to the top, is not blank,
  at 1000 px and at 800 px of width (one column there: the graph above must leave
  the view in sight), and docs/images/console/TAB.png exists; with
  ``RWT_UPDATE_SCREENSHOTS=1`` the test writes those PNGs (1000x700) instead,
  for docs/console.md.
"""

from __future__ import annotations

import base64
import io
import json
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from .cdp import Browser, CdpError, Page, wait_until
from .conftest import RobotProcess

REPO = Path(__file__).resolve().parents[2]
AXE = REPO / "tests" / "js" / "node_modules" / "axe-core" / "axe.min.js"
SHOTS = REPO / "docs" / "images" / "console"
SHOT_SIZE = (1000, 700)
UPDATE = os.environ.get("RWT_UPDATE_SCREENSHOTS") == "1"

# a panel is settled once its images have pixels and its videos a frame
SETTLED = """(() => {
  const panel = document.getElementById(%s);
  if (!panel || panel.hidden) return false;
  const images = [...panel.querySelectorAll('img')];
  const videos = [...panel.querySelectorAll('video')];
  return images.every((i) => i.complete && i.naturalWidth > 0)
    && videos.every((v) => v.readyState >= 2);
})()"""


@pytest.fixture(scope="module")
def page(browser: Browser, video_server: tuple[str, str], robot: RobotProcess) -> Iterator[Page]:
    ws_url, _ = video_server
    page = browser.new_page()
    page.goto(ws_url.replace("ws://", "http://") + "/")
    page.wait_for("!!document.querySelector('#status.ok')", what="the console to connect")
    # something in the views that need a choice: a topic's echo and plot, a service's form
    page.click('#topics tbody tr[data-name="/console_test/point"]')
    page.wait_for("document.querySelectorAll('#echo-output .message').length > 0")
    page.click('#services li[data-name="/console_test/add"]')
    page.wait_for("!document.getElementById('service-form').hidden")
    yield page
    page.close()


def tabs(page: Page) -> list[tuple[str, str]]:
    """The (tab name, panel id) of every tab in the page's tablist."""
    found = page.evaluate(
        "[...document.querySelectorAll('[role=tablist] [role=tab]')]"
        ".map((t) => [t.dataset.tab || t.id, t.getAttribute('aria-controls')])"
    )
    assert found, "the console has no tablist"
    return [(name, panel) for name, panel in found]


def select(page: Page, name: str, panel: str) -> None:
    """Open one tab as a user would, and wait until its panel settled."""
    page.click(f'[role=tablist] [role=tab][aria-controls="{panel}"]')
    page.wait_for(SETTLED % json.dumps(panel), 20, f"the {name} panel to settle")


def resize(page: Page, width: int, height: int) -> None:
    page.send(
        "Emulation.setDeviceMetricsOverride",
        width=width,
        height=height,
        deviceScaleFactor=1,
        mobile=False,
    )


def visible_part(page: Page, panel: str) -> bytes | None:
    """A PNG of what the window shows of ``panel`` scrolled to the top, as a user opening
    the page sees it; None when (almost) nothing of it is in view."""
    page.evaluate("window.scrollTo(0, 0)")
    x, y, width, height = page.evaluate(
        f"(r => [r.left, Math.max(r.top, 0), r.width, Math.min(r.bottom, innerHeight)"
        f" - Math.max(r.top, 0)])(document.getElementById({json.dumps(panel)})"
        ".getBoundingClientRect())"
    )
    if width < 50 or height < 50:
        return None
    clip = {"x": x, "y": y, "width": width, "height": height, "scale": 1}
    return base64.b64decode(page.send("Page.captureScreenshot", format="png", clip=clip)["data"])


def blank(png: bytes | None) -> bool:
    """Whether an image is (nearly) one colour: under 0.5 % of it differs from its
    most common colour (or there is no image)."""
    if png is None:
        return True
    pixels = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).reshape(-1, 3)
    colours, counts = np.unique(pixels, axis=0, return_counts=True)
    background = colours[counts.argmax()]
    differs = np.any(np.abs(pixels.astype(int) - background) > 16, axis=1)
    return bool(differs.mean() < 0.005)


def save_small(png: bytes, path: Path) -> None:
    """Write ``png`` with a palette of 256 colours: a few tens of KB for the docs."""
    image = Image.open(io.BytesIO(png)).convert("RGB").quantize(256)
    image.save(path, optimize=True)


def test_no_serious_or_critical_accessibility_violation_on_any_tab(page: Page) -> None:
    if not AXE.exists():
        pytest.skip("axe-core is not installed (npm ci --prefix tests/js)")
    page.send("Page.setBypassCSP", enabled=True)  # evaluated scripts only; the page keeps its CSP
    page.evaluate(AXE.read_text("utf-8") + ";true")
    found: dict[str, list[str]] = {}
    for name, panel in tabs(page):
        select(page, name, panel)
        violations = page.evaluate(
            "axe.run(document, {resultTypes: ['violations']}).then((r) => r.violations"
            ".filter((v) => v.impact === 'serious' || v.impact === 'critical')"
            ".map((v) => `${v.id} (${v.impact}): `"
            " + v.nodes.map((n) => n.target.join(' ')).join(', ')))"
        )
        if violations:
            found[name] = violations
    assert found == {}, json.dumps(found, indent=1)


@pytest.mark.parametrize("width", [1000, 800])
def test_every_tab_has_a_screenshot_and_renders_something(page: Page, width: int) -> None:
    resize(page, width, SHOT_SIZE[1])
    missing, empty = [], []
    try:
        for name, panel in tabs(page):
            select(page, name, panel)
            try:  # views that subscribe as they open fill in as messages come
                wait_until(lambda p=panel: not blank(visible_part(page, p)), 10, name)
            except CdpError:
                empty.append(name)
            path = SHOTS / f"{name}.png"
            if UPDATE and width == SHOT_SIZE[0]:
                SHOTS.mkdir(parents=True, exist_ok=True)
                save_small(page.viewport_png(), path)
            elif not path.exists():
                missing.append(str(path.relative_to(REPO)))
    finally:
        page.send("Emulation.clearDeviceMetricsOverride")
    assert empty == [], f"blank panels at {width} px: {empty}"
    assert missing == [], f"no screenshot (RWT_UPDATE_SCREENSHOTS=1 writes them): {missing}"
