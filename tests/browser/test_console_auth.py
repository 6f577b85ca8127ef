"""The console of a server that asks for rosauth, with parameters and an action (docs/console.md).

The page asks for the signed ``auth`` op; a wrong one is refused, the right one
connects; then the parameters are listed and a Fibonacci goal shows its feedback
and its result; the Images panel shows a camera through a video token.
"""

from __future__ import annotations

import io
import json
import re
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from PIL import Image

from rwt_protocol.auth import rosauth_op
from rwt_protocol.codecs.json import op_object
from rwt_video.tokens import TOKEN_CHARS
from tests.integration.client_harness import ServerProcess

from .cdp import Browser, Page
from .served_robot import BLUE, RED

SECRET = "console-secret-0123456789"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    script = Path(__file__).with_name("served_robot.py")
    workdir = tmp_path_factory.mktemp("served")
    process = ServerProcess(workdir, cmd=[sys.executable, str(script), SECRET])
    try:
        yield process.url.replace("ws://", "http://") + "/"
    finally:
        process.stop()


def auth_op(secret: str) -> str:
    now = time.time()
    op = rosauth_op(
        secret,
        client="127.0.0.1",
        dest="127.0.0.1",
        rand="r4nd",
        t=now,
        level="admin",
        end=now + 60,
    )
    return json.dumps(op_object(op))


def authenticate(page: Page, secret: str) -> None:
    page.wait_for("!document.getElementById('auth').hidden", what="the auth form")
    assert page.text("#status") == "authentication needed"
    page.fill("#auth-json", auth_op(secret))
    page.click('#auth button[type="submit"]')


@pytest.fixture(scope="module")
def page(browser: Browser, server: str) -> Iterator[Page]:
    page = browser.new_page()
    yield page
    page.close()


def test_a_wrong_mac_is_refused(page: Page, server: str) -> None:
    page.goto(server)
    authenticate(page, "not-the-secret")
    page.wait_for("document.getElementById('status').textContent.startsWith('refused')")
    assert page.text("#auth-error").startswith("the server refused this auth op: ")
    assert page.evaluate("document.querySelectorAll('#topics tbody tr').length") == 0


def test_a_second_try_connects_and_never_puts_the_op_in_the_url(page: Page) -> None:
    # the page from the refusal above: the form stays and takes the right op
    page.fill("#auth-json", auth_op(SECRET))
    page.click('#auth button[type="submit"]')
    page.wait_for("!!document.querySelector('#status.ok')", what="the console to connect")
    assert page.evaluate("location.search") == ""  # not submitted as a GET
    assert page.text("#auth-error") == ""


def test_the_signed_op_connects(page: Page, server: str) -> None:
    page.goto(server)
    authenticate(page, SECRET)
    page.wait_for("!!document.querySelector('#status.ok')", what="the console to connect")
    assert page.evaluate("document.getElementById('auth').hidden")
    page.wait_for("!!document.querySelector('#actions li[data-name=\"/fibonacci\"]')")
    assert page.errors() == []


def test_lists_parameters_with_values(page: Page) -> None:
    rows = page.wait_for(
        "(r => r.length && r)([...document.querySelectorAll('#params tr')]"
        ".map(tr => [...tr.cells].map(c => c.textContent)))",
        what="the parameters",
    )
    values = dict(rows)
    assert json.loads(values["/robot:max_speed"]) == 1.5
    assert json.loads(values["/robot:name"]) == "console-bot"


def test_sends_an_action_goal_and_shows_feedback_and_result(page: Page) -> None:
    page.click('#actions li[data-name="/fibonacci"]')
    page.wait_for("!!document.querySelector('#action-fields input[name=\"goal.order\"]')")
    page.fill('#action-fields input[name="goal.order"]', "6")
    page.click("#action-send")
    page.wait_for(
        "document.getElementById('action-result').textContent.includes('status')",
        what="the result",
    )
    feedback = page.evaluate("document.querySelectorAll('#action-feedback .message').length")
    assert feedback == 5  # one per new term
    result = page.evaluate(
        "[...document.querySelectorAll('#action-result .leaf .v-number')].map(e => e.textContent)"
    )
    assert result == ["0", "1", "1", "2", "3", "5", "8"]
    assert "status 4" in page.text("#action-result")  # SUCCEEDED
    assert page.errors() == []


def test_the_images_panel_shows_frames_through_a_video_token(page: Page) -> None:
    """With auth on the video port wants a token: the page gets one over its connection."""
    page.click('#tabs button[data-tab="images"]')
    selector = '#images figure[data-topic="/camera/image"] img'
    page.wait_for(
        f"(i => i && i.naturalWidth > 0)(document.querySelector('{selector}'))",
        what="the MJPEG image",
    )
    src = page.evaluate(f"document.querySelector('{selector}').src")
    assert re.search(rf"[?&]token=[\w-]{{{TOKEN_CHARS}}}(&|$)", src), src
    shot = Image.open(io.BytesIO(page.screenshot(selector))).convert("RGB")
    width, height = shot.size
    left = shot.getpixel((width // 4, height // 2))
    right = shot.getpixel((3 * width // 4, height // 2))
    assert all(abs(a - b) < 40 for a, b in zip(left, RED, strict=True)), left
    assert all(abs(a - b) < 40 for a, b in zip(right, BLUE, strict=True)), right
    assert page.errors() == []
