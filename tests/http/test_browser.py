"""Chromium's fetch and EventSource against the HTTP API: no client library, a page."""

from __future__ import annotations

import anyio
import pytest

from rwt_graph.graph import Graph
from tests.browser.cdp import Browser, chromium_path

from .support import api_server

pytestmark = pytest.mark.anyio

_STREAM = """
window.got = [];
window.source = new EventSource("/api/topics/robot/say/events");
source.onmessage = (event) => got.push(JSON.parse(event.data).data);
new Promise((ready) => { source.onopen = () => ready(true); });
"""

_PUBLISH = """
fetch("/api/topics/robot/say", {method: "POST", body: JSON.stringify({data: "from the page"})})
  .then((response) => response.json())
"""

_CALL = """
fetch("/api/services/robot/enable", {method: "POST", body: '{"data": true}'})
  .then(async (response) => [response.status, await response.json()])
"""


async def test_a_page_streams_publishes_and_calls_with_fetch_and_event_source() -> None:
    executable = chromium_path()
    if executable is None:
        pytest.skip("chromium is not installed (apt-get install chromium)")
    graph = Graph()
    graph.create_subscription("/robot/say", lambda msg: None, "std_msgs/msg/String")
    graph.create_service("/robot/enable", "std_srvs/srv/SetBool", lambda r: {"success": True})
    async with api_server(graph) as (_, url):

        def in_the_page() -> tuple[object, object, object]:
            browser = Browser(executable)
            try:
                page = browser.new_page()
                page.goto(f"{url}/api/topics")  # the page's origin is the server's
                assert page.evaluate(_STREAM) is True
                published = page.evaluate(_PUBLISH)
                got = page.wait_for("got.length && got", what="the event")
                called = page.evaluate(_CALL)
                page.evaluate("source.close()")
                return published, got, called
            finally:
                browser.close()

        published, got, called = await anyio.to_thread.run_sync(in_the_page)
    assert published == {"topic": "/robot/say", "type": "std_msgs/msg/String"}
    assert got == ["from the page"]
    assert called == [200, {"success": True, "message": ""}]
