"""The real Foxglove client in Node (@foxglove/ws-protocol) against `rwt serve`.

tests/js/foxglove.mjs drives it. Schemas are parsed by @foxglove/rosmsg and payloads decoded by
@foxglove/rosmsg2-serialization, as Foxglove and Lichtblick do; the rosbridge
side is roslib (Node) and roslibpy on the same port.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.integration.client_harness import (
    DRIVER_TIMEOUT,
    JS_DIR,
    Driver,
    ServerProcess,
    node_missing_reason,
)

pytestmark = pytest.mark.node

SCRIPT = JS_DIR / "foxglove.mjs"


def _missing() -> str | None:
    if (reason := node_missing_reason()) is not None:
        return reason
    if not (JS_DIR / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
        return "tests/js/node_modules lacks @foxglove/ws-protocol: run `npm ci --prefix tests/js`"
    return None


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    if (reason := _missing()) is not None:
        pytest.skip(reason)
    # no assets: a sourced ROS environment (AMENT_PREFIX_PATH) would announce them
    process = ServerProcess(tmp_path_factory.mktemp("foxglove"), ("--no-assets",))
    try:
        yield process
    finally:
        process.stop()


def run(scenario: str, url: str, *args: str) -> dict:
    node = shutil.which("node")
    assert node is not None
    done = subprocess.run(
        [node, str(SCRIPT), scenario, url, *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        cwd=JS_DIR,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])["result"]  # type: ignore[no-any-return]


@pytest.mark.parametrize(
    "offered",
    ["foxglove.sdk.v1", "foxglove.websocket.v1", "foxglove.websocket.v1,foxglove.sdk.v1"],
)
def test_handshake_server_info_and_parseable_schemas(server: ServerProcess, offered: str) -> None:
    result = run("handshake", server.url, offered)
    assert result["protocol"] == offered.split(",", maxsplit=1)[0]
    info = result["serverInfo"]
    assert info["name"] == "rwt" and info["capabilities"] == ["clientPublish"]
    assert info["supportedEncodings"] == ["cdr", "json"] and info["sessionId"]
    assert result["string"] == {
        "encoding": "cdr",
        "schemaName": "std_msgs/msg/String",
        "schemaEncoding": "ros2msg",
        "types": [{"name": None, "fields": ["string data"]}],
    }
    image = result["image"]
    assert image["schemaName"] == "sensor_msgs/msg/Image"
    names = [each["name"] for each in image["types"]]
    assert names == [None, "std_msgs/Header", "builtin_interfaces/Time"]
    assert image["types"][1]["fields"] == ["time stamp", "string frame_id"]
    assert image["types"][2]["fields"] == ["int32 sec", "uint32 nanosec"]


def test_subscribe_in_order_a_2mb_image_unsubscribe_and_topics_that_come_and_go(
    server: ServerProcess,
) -> None:
    result = run("stream", server.url)
    assert result["got"] == ["one", "two", "three", "four", "five"]
    assert result["image"] == {
        "stamp": [1_700_000_000, 5],
        "frame_id": "cam",
        "size": [1024, 1024, 2048],
        "length": 2 * 1024 * 1024,
        "intact": True,
        "logTimeOk": True,
    }
    assert result["afterUnsubscribe"] == []
    assert result["late"]["advertised"] == "std_msgs/msg/Int32"
    assert result["errors"] == []


def test_bad_inputs_each_get_a_status_and_the_connection_goes_on(server: ServerProcess) -> None:
    result = run("bad", server.url)
    expected = {
        "unknownOp": "unknown op 'frobnicate'",
        "malformedJson": "invalid JSON",
        "unknownOpcode": "unknown binary opcode 0x7f",
        "unknownChannel": "unknown channel 424242",
        "unknownSubscription": "unknown subscription 31337",
        "unknownClientChannel": "unknown client channel 1337",
        "truncatedBinary": "shorter than its 5-byte header",
        "hugeLength": "name longer than",
        "hugeId": "not a 32-bit unsigned integer",
        "loneSurrogate": "lone surrogate",
        "hugeInt": "does not fit in 64 bits",
    }
    for name, text in expected.items():
        status = result["answers"][name]
        assert status["level"] == 2 and text in status["message"], (name, status)
    assert result["latched"] == "still here"
    assert result["open"] is True


def test_client_publish_in_cdr_and_json_reaches_roslibpy(
    server: ServerProcess, tmp_path: Path
) -> None:
    steps = [
        {"op": "connect", "conn": "sub"},
        {"op": "subscribe", "conn": "sub", "topic": "/fg_from_fox", "type": "std_msgs/String"},
        {"op": "sync", "conn": "sub"},
        {"op": "signal", "name": "ready"},
        {"op": "await"},
        {"op": "wait", "conn": "sub", "topic": "/fg_from_fox", "count": 2},
        {"op": "quiet", "ms": 300},
    ]
    driver = Driver("roslibpy", server.url, steps, tmp_path, "roslibpy-sub")
    try:
        deadline = time.monotonic() + DRIVER_TIMEOUT
        driver.wait_event("ready", deadline)
        result = run("publish", server.url)
        driver.go()
        received = driver.wait_result(deadline)["received"]["sub"]["/fg_from_fox"]
    except AssertionError:
        print(driver.describe())
        raise
    finally:
        driver.kill()
    assert received == [{"data": "from cdr"}, {"data": "from json"}]
    assert "unknown client channel" in result["status"]["message"]
