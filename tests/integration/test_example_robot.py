"""examples/robot.py (the README's robot in under 30 lines) driven by a raw WebSocket client."""

from __future__ import annotations

import json
import sys
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest
from websockets.sync.client import ClientConnection, connect

from .client_harness import REPO, ServerProcess

EXAMPLE = REPO / "examples" / "robot.py"
TIMEOUT_S = 10.0
#: The parameter services a node with parameters answers, sorted.
PARAM_PARTS = [
    "describe_parameters",
    "get_parameter_types",
    "get_parameters",
    "list_parameters",
    "set_parameters",
    "set_parameters_atomically",
]


@pytest.fixture
def robot(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ServerProcess]:
    server = ServerProcess(tmp_path, cmd=[sys.executable, str(EXAMPLE), "0"])
    request.node._rwt_server = server
    try:
        yield server
    finally:
        server.stop()


def send(ws: ClientConnection, **op: object) -> None:
    ws.send(json.dumps(op))


def expect(ws: ClientConnection, op: str) -> dict:
    """The next frame with this op (every wait bounded)."""
    while True:
        frame = json.loads(ws.recv(timeout=TIMEOUT_S))
        if frame["op"] == op:
            return frame


def rosapi(ws: ClientConnection, service: str, **args: object) -> dict:
    send(ws, op="call_service", service=service, args=args, id=service)
    reply = expect(ws, "service_response")
    assert reply["id"] == service and reply["result"] is True, reply
    return reply["values"]


def test_the_example_is_about_30_lines() -> None:
    # the README's claim
    assert len(EXAMPLE.read_text().splitlines()) <= 31


def test_its_port_serves_the_web_console(robot: ServerProcess) -> None:
    # as rwt serve's does (docs/console.md): a browser opening the WebSocket port gets the page
    base = robot.url.replace("ws://", "http://").rstrip("/") + "/"
    with urllib.request.urlopen(base, timeout=TIMEOUT_S) as page:
        assert page.status == 200 and "text/html" in page.headers["Content-Type"]
        assert b"rwt" in page.read()
    with urllib.request.urlopen(f"{base}console/config.json", timeout=TIMEOUT_S) as config:
        assert json.loads(config.read())["websocket"]["path"] == "/"


def test_topics_service_action_and_parameters(robot: ServerProcess) -> None:
    with connect(robot.url) as ws:
        send(ws, op="subscribe", topic="/velocity")
        send(ws, op="advertise", topic="/cmd_vel", type="geometry_msgs/Twist")
        send(ws, op="publish", topic="/cmd_vel", msg={"linear": {"x": 0.5}})
        velocity = expect(ws, "publish")
        assert velocity["topic"] == "/velocity"
        assert velocity["msg"]["linear"] == {"x": 0.5, "y": 0.0, "z": 0.0}

        send(ws, op="call_service", service="/lights", args={"data": True}, id="l")
        lights = expect(ws, "service_response")
        assert lights["values"] == {"success": True, "message": ""} and lights["result"] is True

        send(
            ws,
            op="send_action_goal",
            action="/fibonacci",
            action_type="example_interfaces/action/Fibonacci",
            args={"order": 5},
            feedback=True,
            id="g",
        )
        assert expect(ws, "action_feedback")["values"] == {"sequence": [0, 1, 1]}
        result = expect(ws, "action_result")
        assert result["status"] == 4 and result["result"] is True
        assert result["values"] == {"sequence": [0, 1, 1, 2, 3, 5]}

        assert rosapi(ws, "/rosapi/get_param", name="/rwt:max_speed")["value"] == "1.0"
        assert rosapi(ws, "/rosapi/set_param", name="/rwt:max_speed", value="2.5") == {
            "successful": True,
            "reason": "",
        }
        assert rosapi(ws, "/rosapi/get_param", name="/rwt:max_speed")["value"] == "2.5"
        assert rosapi(ws, "/rosapi/action_servers") == {
            "action_servers": ["/fibonacci", "/tf2_web_republisher"]  # built in, REF §7.3
        }
        assert rosapi(ws, "/rosapi/node_details", node="/rwt") == {
            "subscribing": ["/cmd_vel"],
            "publishing": ["/velocity"],
            "services": ["/lights", *(f"/rwt/{part}" for part in PARAM_PARTS)],
        }
        listed = rosapi(ws, "/rwt/list_parameters")  # as a ROS 2 node's (docs/agents.md)
        assert listed == {"result": {"names": ["max_speed", "name"], "prefixes": []}}


def test_the_readme_points_to_the_example() -> None:
    assert f"`{EXAMPLE.relative_to(REPO)}`" in (REPO / "README.md").read_text()
