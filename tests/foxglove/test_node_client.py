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

from tests.foxglove import extras
from tests.foxglove.extras import missing
from tests.integration.client_harness import (
    DRIVER_TIMEOUT,
    JS_DIR,
    Driver,
    ServerProcess,
    _LineReader,
)

pytestmark = pytest.mark.node

SCRIPT = JS_DIR / "foxglove.mjs"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    if (reason := missing()) is not None:
        pytest.skip(reason)
    # no assets: a sourced ROS environment (AMENT_PREFIX_PATH) would announce them; rosapi's
    # services show to the Foxglove client (test_plumbing.py)
    process = ServerProcess(
        tmp_path_factory.mktemp("foxglove"), ("--no-assets", "--foxglove-show-plumbing")
    )
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


class Scenario:
    """A foxglove.mjs scenario running beside the test: its events, then its result."""

    def __init__(self, scenario: str, url: str) -> None:
        node = shutil.which("node")
        assert node is not None
        self.proc = subprocess.Popen(
            [node, str(SCRIPT), scenario, url],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            cwd=JS_DIR,
        )
        self._lines = _LineReader(self.proc.stdout, f"foxglove-{scenario}")

    def _next(self, deadline: float) -> dict:
        line = self._lines.get(deadline)
        if line is None:
            self.proc.wait(5)
            assert self.proc.stderr is not None
            raise AssertionError(f"node exited: {self.proc.stderr.read().decode()}")
        return json.loads(line)  # type: ignore[no-any-return]

    def wait_event(self, name: str, deadline: float) -> dict:
        """The next line, which must be event ``name`` (with whatever it tells)."""
        frame = self._next(deadline)
        assert frame.get("event") == name, frame
        return frame

    def result(self, deadline: float) -> dict:
        frame = self._next(deadline)
        assert self.proc.wait(max(0.1, deadline - time.monotonic())) == 0
        return frame["result"]  # type: ignore[no-any-return]

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)
        for pipe in (self.proc.stdout, self.proc.stderr):
            if pipe is not None:
                pipe.close()


@pytest.mark.parametrize(
    "offered",
    ["foxglove.sdk.v1", "foxglove.websocket.v1", "foxglove.websocket.v1,foxglove.sdk.v1"],
)
def test_handshake_server_info_and_parseable_schemas(server: ServerProcess, offered: str) -> None:
    result = run("handshake", server.url, offered)
    assert result["protocol"] == offered.split(",", maxsplit=1)[0]
    info = result["serverInfo"]
    assert info["name"] == "rwt"
    assert info["capabilities"] == [
        "clientPublish",
        "services",
        "connectionGraph",
        "parameters",
        "parametersSubscribe",
    ]
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
        "hugeLengthInBinary": "past the frame's end",
        "hugeCdrLength": "not a cdr message",
        "hugeId": "not a 32-bit unsigned integer",
        "loneSurrogate": "lone surrogate",
        "hugeInt": "does not fit in 64 bits",
    }
    for name, text in expected.items():
        status = result["answers"][name]
        assert status["level"] == 2 and text in status["message"], (name, status)
    assert result["latched"] == "still here"
    assert result["open"] is True


def test_two_clients_are_independent(server: ServerProcess) -> None:
    result = run("two", server.url)
    # each got its own subscriptions' messages, in order; the other's take nothing from it
    assert result["oneGot"] == ["a:a1", "a:a2"]
    assert result["otherGot"] == ["a:a1", "b:b1", "a:a2"]
    # one unsubscribed, then left: nothing more for it, and the other goes on
    assert result["oneAfter"] == []
    assert result["otherAfter"] == ["a:a3", "b:b2"]
    assert result["otherLast"] == ["a:a4"]
    assert result["statuses"] == 4  # the probes' only (3 and 1)


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


ADD = "example_interfaces/srv/AddTwoInts"
BIG = 2**62 + 1


def test_service_calls_answered_by_roslibpy_providers_by_call_id(
    server: ServerProcess, tmp_path: Path
) -> None:
    providers = [
        {"op": "connect", "conn": "p"},
        {"op": "advertise_service", "conn": "p", "service": "/fg_add", "type": ADD, "reply": "add"},
        {
            "op": "advertise_service",
            "conn": "p",
            "service": "/fg_refuse",
            "type": "std_srvs/srv/SetBool",
            "reply": "refuse",
        },
        {"op": "sync", "conn": "p"},
        {"op": "signal", "name": "ready"},
        {"op": "await"},
    ]
    holder = [
        {"op": "connect", "conn": "h"},
        {
            "op": "advertise_service",
            "conn": "h",
            "service": "/fg_hold",
            "type": ADD,
            "reply": "hold",
        },
        {"op": "sync", "conn": "h"},
        {"op": "signal", "name": "ready"},
        {"op": "wait_served", "conn": "h", "service": "/fg_hold", "count": 1},
        {"op": "signal", "name": "held"},
        {"op": "await"},
    ]
    deadline = time.monotonic() + DRIVER_TIMEOUT
    drivers = [
        Driver("roslibpy", server.url, providers, tmp_path, "providers"),
        Driver("roslibpy", server.url, holder, tmp_path, "holder"),
    ]
    scenario = None
    try:
        for driver in drivers:
            driver.wait_event("ready", deadline)
        scenario = Scenario("services", server.url)
        scenario.wait_event("answered", deadline)
        drivers[1].wait_event("held", deadline)
        drivers[1].kill()  # the provider of /fg_hold goes with call 1 in flight
        result = scenario.result(deadline)
        drivers[0].go()
        served = drivers[0].wait_result(deadline)["served"]["p"]
    except AssertionError:
        for driver in drivers:
            print(driver.describe())
        raise
    finally:
        if scenario is not None:
            scenario.kill()
        for driver in drivers:
            driver.kill()
    assert result["add"] == {
        "type": ADD,
        "request": ["cdr", f"{ADD}_Request", "ros2msg"],
        "response": ["cdr", f"{ADD}_Response", "ros2msg"],
    }
    assert result["refuse"]["type"] == "std_srvs/srv/SetBool"
    answers = result["answers"]
    assert answers["2"] == {"sum": str(BIG + 1), "encoding": "cdr"}
    assert answers["3"] == {"sum": "-2", "encoding": "cdr"}
    assert answers["4"] == {"failure": "service call failed", "serviceId": result["ids"][1]}
    assert answers["5"]["failure"] == "unknown service 999999"
    assert answers["6"]["failure"] == "unsupported encoding 'json' (expected cdr)"
    assert "bad request" in answers["7"]["failure"]
    assert "provider disconnected" in answers["1"]["failure"]
    assert answers["1"]["serviceId"] == result["ids"][2]
    assert result["order"][-1] == 1  # the others were answered while it waited
    assert served["/fg_add"] == [{"a": BIG, "b": 1}, {"a": -5, "b": 3}]


def test_the_servers_own_service_answers_a_foxglove_call(server: ServerProcess) -> None:
    got = extras.run("call", server.url, "/rosapi/topics", "{}")
    assert got["type"] == "rosapi_msgs/srv/Topics" and got["failure"] is None
    listed = dict(zip(got["response"]["topics"], got["response"]["types"], strict=True))
    assert listed["/client_count"] == "std_msgs/msg/Int32"


def test_parameters_set_get_and_updates_from_rosapi_and_another_client(
    server: ServerProcess, tmp_path: Path
) -> None:
    driver = None
    scenario = Scenario("params", server.url)
    try:
        deadline = time.monotonic() + DRIVER_TIMEOUT
        node = scenario.wait_event("subscribed", deadline)["node"]
        # roslibpy changes the parameter the Foxglove client created on its own node
        steps = [
            {"op": "connect", "conn": "c"},
            {
                "op": "api",
                "conn": "c",
                "call": "set_param",
                "args": [f"{node}:fg_gain", 2.75],
                "as": "set",
            },
        ]
        driver = Driver("roslibpy", server.url, steps, tmp_path, "roslibpy-params")
        assert driver.wait_result(deadline)["calls"]["set"]["ok"]["successful"] is True
        result = scenario.result(deadline)
    except AssertionError:
        if driver is not None:
            print(driver.describe())
        raise
    finally:
        scenario.kill()
        if driver is not None:
            driver.kill()
    assert (
        "parameters" in result["capabilities"] and "parametersSubscribe" in result["capabilities"]
    )
    assert node.startswith("/rwt_client_")
    assert (
        result["status"]["level"] == 2
        and "node /fg_ghost does not exist" in result["status"]["message"]
    )
    assert result["server"]["level"] == 2
    assert "node /rosapi is the server's" in result["server"]["message"]
    gain = {"name": f"{node}.fg_gain", "value": 1, "type": "float64"}  # 1.0: JSON writes it 1
    assert result["set"] == [gain, {"name": f"{node}.fg_mode", "value": "auto"}]
    assert result["got"] == result["set"]
    assert result["fromRosapi"] == [{"name": f"{node}.fg_gain", "value": 2.75, "type": "float64"}]
    assert result["fromOther"] == [{"name": f"{node}.fg_mode", "value": "manual"}]


def test_connection_graph_shows_a_roslibpy_publisher_come_and_go(
    server: ServerProcess, tmp_path: Path
) -> None:
    steps = [
        {"op": "connect", "conn": "p"},
        {"op": "signal", "name": "ready"},
        {"op": "await"},
        {"op": "advertise", "conn": "p", "topic": "/fg_graph_topic", "type": "std_msgs/String"},
        {"op": "sync", "conn": "p"},
        {"op": "await"},
        {"op": "close", "conn": "p"},
    ]
    driver = Driver("roslibpy", server.url, steps, tmp_path, "roslibpy-graph")
    scenario = None
    try:
        deadline = time.monotonic() + DRIVER_TIMEOUT
        driver.wait_event("ready", deadline)
        scenario = Scenario("graph", server.url)
        scenario.wait_event("following", deadline)
        driver.go()
        scenario.wait_event("seen", deadline)
        driver.go()
        result = scenario.result(deadline)
        driver.wait_result(deadline)
    except AssertionError:
        print(driver.describe())
        raise
    finally:
        if scenario is not None:
            scenario.kill()
        driver.kill()
    first = result["first"]
    assert "/rosapi/topics" in first["services"] and first["removedTopics"] == []
    assert "/client_count" in first["published"] and "/fg_graph_topic" not in first["published"]
    [publisher] = result["publishers"]
    assert publisher.startswith("/rwt_client_")
    assert "/fg_graph_topic" in result["removedTopics"]  # with the sync topic of roslibpy's driver
