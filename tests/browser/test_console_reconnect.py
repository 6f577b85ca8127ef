"""The console reconnects by itself after the server goes and comes back (docs/console.md).

A page watches a topic; the server stops (the page says it reconnects, with the
delay); a new server starts on the same port; the page connects again on its own,
says so, and its echo of the topic goes on (the subscription was sent again).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tests.integration.client_harness import ServerProcess

if TYPE_CHECKING:
    from pathlib import Path

    from .cdp import Browser

ROW = '#topics tbody tr[data-name="/client_count"]'


def test_the_page_reconnects_and_subscribes_again(browser: Browser, tmp_path: Path) -> None:
    first = ServerProcess(tmp_path)
    port = first.port
    page = browser.new_page()
    second = None
    try:
        page.goto(f"http://127.0.0.1:{port}/")
        page.wait_for("!!document.querySelector('#status.ok')", what="the first connection")
        page.click(ROW)
        page.wait_for("/data: 1/.test(document.querySelector('#echo-output').textContent)")
        first.stop()
        status = page.wait_for(
            "(t => t.includes('reconnecting in') && t)"
            "(document.getElementById('status').textContent)",
            what="the page saying it reconnects",
        )
        assert status.startswith("disconnected")
        page.evaluate("document.getElementById('echo-output').replaceChildren()")
        second = ServerProcess(tmp_path, ("--port", str(port)))
        page.wait_for(
            "!!document.querySelector('#status.ok')", timeout_s=60, what="the page reconnected"
        )
        # the topic view's subscription went again: the new server's latched count
        page.wait_for(
            "/data: 1/.test(document.querySelector('#echo-output').textContent)",
            what="the echo going on after the reconnect",
        )
        # Chromium reports each attempt made while no server listened; nothing else
        assert [e for e in page.errors() if "ERR_CONNECTION_REFUSED" not in e] == []
    finally:
        page.close()
        for server in (first, second):
            if server is not None:
                server.stop()
