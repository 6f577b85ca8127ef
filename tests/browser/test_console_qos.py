"""The console shows a topic's missed deadline (protocol 2.1.0's ``qos``, D65), in Chromium.

A robot's program (a plain WebSocket client) advertises ``/beat`` with a deadline of
0.5 s and publishes once. A person opens the console, picks ``/beat`` in the topic
list (the console subscribes without ``qos``, so the topic's offered deadline is its
deadline) and the topic falls silent: the Server tab's "Messages from the server"
shows the server's warning. The robot's program, which asked for warnings, is told
too that it missed the deadline it offered (ROS 2's "offered deadline missed").
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from websockets.sync.client import connect

from tests.integration.client_harness import ServerProcess

if TYPE_CHECKING:
    from pathlib import Path

    from websockets.sync.client import ClientConnection

    from .cdp import Browser

MISSED = "subscribe: /beat missed its deadline: no message for 0.5 s"
LOG = "document.getElementById('server-log').textContent"


def _next_status(ws: ClientConnection) -> dict[str, object]:
    while True:
        op = json.loads(ws.recv(timeout=20))
        if op["op"] == "status":
            return op  # type: ignore[no-any-return]


def test_the_console_shows_a_topics_missed_deadline(browser: Browser, tmp_path: Path) -> None:
    server = ServerProcess(tmp_path)
    page = browser.new_page()
    try:
        with connect(server.url, open_timeout=20) as robot:
            robot.send(json.dumps({"op": "set_level", "level": "warning"}))
            advertise = {
                "op": "advertise",
                "topic": "/beat",
                "type": "std_msgs/String",
                "qos": {"deadline": 0.5},
                "id": "beat",
            }
            robot.send(json.dumps(advertise))
            robot.send(json.dumps({"op": "publish", "topic": "/beat", "msg": {"data": "one"}}))
            page.goto(server.url.replace("ws://", "http://") + "/")
            page.wait_for("!!document.querySelector('#status.ok')", what="the console to connect")
            page.click('#topics tbody tr[data-name="/beat"]')
            page.click('[role=tablist] [data-tab="server"]')
            shown = page.wait_for(
                f"(t => t.includes({json.dumps(MISSED)}) && t)({LOG})",
                timeout_s=30,
                what="the missed deadline in the Server tab",
            )
            assert "warning: " + MISSED in shown
            # the warning is where a person looks: the Server tab is open and shows the list
            assert page.evaluate(
                "!document.getElementById('tab-server').hidden"
                " && document.getElementById('server-log').getClientRects().length > 0"
            )
            assert _next_status(robot) == {
                "op": "status",
                "level": "warning",
                "msg": "advertise: /beat missed its offered deadline: nothing published for 0.5 s",
                "id": "beat",
            }
        assert page.errors() == []
    finally:
        page.close()
        server.stop()
