"""examples/embedded_server.py: Python publishes /counter and prints /cmd_vel from clients."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from websockets.sync.client import connect

from .client_harness import REPO, ServerProcess

EXAMPLE = REPO / "examples" / "embedded_server.py"
TIMEOUT_S = 10.0


@pytest.fixture
def embedded(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ServerProcess]:
    server = ServerProcess(tmp_path, cmd=[sys.executable, str(EXAMPLE), "--port", "0"])
    request.node._rwt_server = server
    try:
        yield server
    finally:
        server.stop()


def test_clients_see_the_counter_and_python_sees_their_commands(embedded: ServerProcess) -> None:
    with connect(embedded.url) as ws:
        ws.send(json.dumps({"op": "subscribe", "topic": "/counter"}))
        first = json.loads(ws.recv(timeout=TIMEOUT_S))
        second = json.loads(ws.recv(timeout=TIMEOUT_S))
        assert first["topic"] == "/counter"
        assert second["msg"]["data"] == first["msg"]["data"] + 1
        ws.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"angular": {"z": 0.5}}}))
        line = embedded.next_stdout_line(TIMEOUT_S)
    assert line is not None and line.startswith("cmd_vel:")
    assert "'z': 0.5" in line
