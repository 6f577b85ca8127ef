"""`rwt serve` as the tests start it: first line, clean stop with clients connected."""

from __future__ import annotations

import json
import signal

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect as ws_connect

from .client_harness import SERVER_STOP_TIMEOUT


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_server_stops_cleanly_with_clients_connected(rwt_server, sig):
    assert rwt_server.url == f"ws://127.0.0.1:{rwt_server.port}"
    with ws_connect(rwt_server.url) as ws:
        ws.send(json.dumps({"op": "subscribe", "topic": "/chatter", "type": "std_msgs/String"}))
        ws.send(json.dumps({"op": "advertise", "topic": "/chatter", "type": "std_msgs/String"}))
        ws.send(json.dumps({"op": "publish", "topic": "/chatter", "msg": {"data": "up"}}))
        assert json.loads(ws.recv(timeout=5))["msg"] == {"data": "up"}

        rwt_server.proc.send_signal(sig)
        code = rwt_server.proc.wait(SERVER_STOP_TIMEOUT)
        assert code == 0, f"exit code {code} on {sig.name}"
        with pytest.raises(ConnectionClosed):
            ws.recv(timeout=5)
    assert "Traceback" not in rwt_server.stderr_text()
