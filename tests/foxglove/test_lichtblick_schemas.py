"""Lichtblick's schema check on what rwt advertises, with the real Foxglove client in Node.

Lichtblick (v1.28.1) preloads its copy of ROS 2 Humble's common definitions (ROS 1's for
``noetic``) when ``serverInfo`` names a ROS distribution, parses each advertised
``ros2msg`` (``ros1msg``) schema with @lichtblick/rosmsg and compares every definition
with the one it holds under that name, member by member and in order
(@lichtblick/message-definition's ``isMsgDefEqual``); a mismatch is the error alert
"Definition of schema 'X' has changed during the server's runtime" (docs/foxglove.md).
tests/js/lichtblick_schemas.mjs replays that rule, with those two packages pinned,
against ``lichtblick_ros2humble.json`` and ``lichtblick_ros1.json``: the repository's
copies of the reference definitions, one ``.msg`` text a type in the file's order.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from rwt_foxglove.schemas import schema_of
from rwt_graph.types import Dialect, TypeRegistry, sources
from tests.foxglove import extras
from tests.foxglove.extras import missing
from tests.integration.client_harness import REPO, ServerProcess

pytestmark = pytest.mark.node

SCRIPT = "lichtblick_schemas.mjs"
REFERENCE = Path(__file__).resolve().parent / "lichtblick_ros2humble.json"
ROS1_REFERENCE = REFERENCE.with_name("lichtblick_ros1.json")
EXAMPLE = REPO / "examples" / "robot.py"
#: A ROS 1 robot (``noetic``) with common types on its topics and a service.
ROS1_ROBOT = """
import asyncio
from rwt import Graph, RosbridgeServer, ServerConfig
from rwt.types import Dialect, TypeRegistry
graph = Graph(TypeRegistry(Dialect.ROS1))
graph.create_publisher("/velocity", "geometry_msgs/Twist")
graph.create_publisher("/fix", "sensor_msgs/NavSatFix")
graph.create_publisher("/markers", "visualization_msgs/MarkerArray")
graph.create_publisher("/scan", "sensor_msgs/LaserScan")
graph.create_service("/lights", "std_srvs/SetBool", lambda req: {"success": True})
server = RosbridgeServer(graph, ServerConfig(port=0))
asyncio.run(server.serve(on_listening=lambda url: print("listening on", url, flush=True)))
"""

#: Where ROS 2 itself changed a common type after Humble: rwt serves Jazzy's (Kilted's)
#: definitions, so Lichtblick flags these whoever serves them (foxglove_bridge on Jazzy too).
#: Each name maps to the members Humble lacks.
CHANGED_SINCE_HUMBLE = {
    "sensor_msgs/msg/BatteryState": {
        "POWER_SUPPLY_TECHNOLOGY_TERNARY",
        "POWER_SUPPLY_TECHNOLOGY_VRLA",
    },
    "sensor_msgs/msg/NavSatStatus": {"STATUS_UNKNOWN", "SERVICE_UNKNOWN"},
    "sensor_msgs/msg/Range": {"variance"},
    "visualization_msgs/msg/Marker": {"ARROW_STRIP"},
}


def run(*args: str) -> Any:
    return extras.run(*args, script=SCRIPT)


#: The one type of Lichtblick's ROS 1 set a ROS 1 graph writes otherwise: a ROS 2 type
#: (no ROS 1 file), whose ``byte`` constants Lichtblick reads as ROS 1's ``byte`` (int8)
#: and rwt writes as ROS 2's (an octet: uint8).
ROS1_DIFFERS = {"rcl_interfaces/Log"}


def reference_types(path: Path = REFERENCE) -> dict[str, str]:
    return json.loads(path.read_text(encoding="utf-8"))["types"]  # type: ignore[no-any-return]


def full(name: str) -> str:
    package, _, short = name.partition("/")
    return f"{package}/msg/{short}"


@pytest.fixture(autouse=True)
def _node() -> None:
    if (reason := missing()) is not None:
        pytest.skip(reason)


@pytest.fixture
def robot(tmp_path: Path) -> Iterator[ServerProcess]:
    server = ServerProcess(tmp_path, cmd=[sys.executable, str(EXAMPLE), "0"])
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture(params=[(), ("--dialect", "ros1")], ids=["ros2", "ros1"])
def default_server(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ServerProcess]:
    server = ServerProcess(tmp_path, request.param)
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def ros1_robot(tmp_path: Path) -> Iterator[ServerProcess]:
    server = ServerProcess(tmp_path, cmd=[sys.executable, "-c", ROS1_ROBOT])
    try:
        yield server
    finally:
        server.stop()


@pytest.mark.parametrize(("name", "path"), [("ros2humble", REFERENCE), ("ros1", ROS1_REFERENCE)])
def test_the_reference_is_lichtblicks_own_set(name: str, path: Path) -> None:
    # parsed by Lichtblick's rule, each type equals @lichtblick/rosmsg-msgs-common's
    result = run("data", name, str(path))
    assert result["types"] == len(reference_types(path)) > 100
    assert result["unequal"] == []
    assert result["extra"] == []


def test_the_example_robot_raises_no_alert(robot: ServerProcess) -> None:
    result = run("server", robot.url, str(REFERENCE), "/velocity", "/lights", "/rwt/get_parameters")
    assert result["distro"] == "kilted"  # so Lichtblick preloads the reference set
    assert result["alerts"] == []
    assert {"/velocity", "/fibonacci/_action/status"} <= set(result["channels"])
    assert {"/lights", "/rwt/set_parameters"} <= set(result["services"])
    # the topics' and the parameter services' types met their reference and were equal
    for name in (
        "geometry_msgs/msg/Twist",
        "geometry_msgs/Vector3",
        "action_msgs/msg/GoalStatusArray",
        "action_msgs/GoalStatus",
        "rcl_interfaces/ParameterDescriptor",
    ):
        assert name in result["compared"]


def test_a_default_server_raises_no_alert(default_server: ServerProcess) -> None:
    ros1 = "--dialect" in default_server.cmd
    result = run("server", default_server.url, str(ROS1_REFERENCE if ros1 else REFERENCE))
    assert result["distro"] == ("noetic" if ros1 else "kilted")
    # its own plumbing (rosapi, the server's parameters) is hidden from Foxglove clients
    assert result["channels"] == [] and result["services"] == []
    assert result["alerts"] == []


def test_the_foxglove_sdk_server_of_the_same_robot_raises_no_fewer(robot: ServerProcess) -> None:
    foxglove = pytest.importorskip("foxglove", reason="the Foxglove SDK (foxglove-sdk) is absent")
    from foxglove.websocket import (  # noqa: PLC0415
        Capability,
        MessageSchema,
        Service,
        ServiceSchema,
    )

    registry = TypeRegistry(Dialect.ROS2)

    def schema(name: str) -> Any:
        text = schema_of(registry.message(name)).schema.encode()
        return foxglove.Schema(name=name, encoding="ros2msg", data=text)

    velocity = foxglove.Channel(
        "/velocity", schema=schema("geometry_msgs/msg/Twist"), message_encoding="cdr"
    )
    lights = Service(
        "/lights",
        schema=ServiceSchema(
            "std_srvs/srv/SetBool",
            request=MessageSchema(encoding="cdr", schema=schema("std_srvs/srv/SetBool_Request")),
            response=MessageSchema(encoding="cdr", schema=schema("std_srvs/srv/SetBool_Response")),
        ),
        handler=lambda request: b"",
    )
    server = foxglove.start_server(
        port=0, capabilities=[Capability.Services], supported_encodings=["cdr"], services=[lights]
    )
    try:
        sdk = run("server", f"ws://127.0.0.1:{server.port}", str(REFERENCE), "/velocity", "/lights")
    finally:
        server.stop()
        velocity.close()
    ours = run("server", robot.url, str(REFERENCE), "/velocity", "/lights")
    assert sdk["channels"] == ["/velocity"] and sdk["services"] == ["/lights"]
    # the SDK names no ROS distribution, so Lichtblick compares nothing with its own set there
    assert sdk["distro"] == "none"
    assert len(ours["alerts"]) <= len(sdk["alerts"])


def test_a_ros1_robot_raises_no_alert(ros1_robot: ServerProcess) -> None:
    names = ["/velocity", "/fix", "/markers", "/scan", "/lights"]
    result = run("server", ros1_robot.url, str(ROS1_REFERENCE), *names)
    assert result["distro"] == "noetic"
    assert result["alerts"] == []
    # Kilted's NavSatStatus differs from Humble's, Noetic's is Lichtblick's ROS 1 copy
    for name in (
        "geometry_msgs/Twist",
        "sensor_msgs/NavSatFix",
        "sensor_msgs/NavSatStatus",
        "visualization_msgs/Marker",
        "sensor_msgs/LaserScan",
        "std_msgs/Header",
    ):
        assert name in result["compared"]


def rwt_schemas(tmp_path: Path, texts: dict[str, str], reference: Path = REFERENCE) -> Any:
    path = tmp_path / "schemas.json"
    path.write_text(json.dumps(texts), encoding="utf-8")
    return run("schemas", str(path), str(reference))


def test_every_common_ros1_type_matches_but_a_ros2_one(tmp_path: Path) -> None:
    # ROS 1 (shape_msgs, visualization_msgs...) in Noetic's order (test_ros1_declaration_order)
    registry = TypeRegistry(Dialect.ROS1)
    known = set(registry.message_names())
    texts = {
        name: schema_of(registry.message(name)).schema
        for name in reference_types(ROS1_REFERENCE)
        if name in known
    }
    assert len(texts) >= len(reference_types(ROS1_REFERENCE)) - 2  # but velodyne_msgs'
    result = rwt_schemas(tmp_path, texts, ROS1_REFERENCE)
    changed = {alert["id"].removeprefix("schema-changed-") for alert in result["alerts"]}
    assert changed == ROS1_DIFFERS
    assert set(texts) <= set(result["compared"])  # each met its reference


def test_every_common_type_matches_but_where_ros_2_changed_it(tmp_path: Path) -> None:
    # a channel of each reference type rwt knows, as rwt advertises it
    registry = TypeRegistry(Dialect.ROS2)
    known = set(registry.message_names())
    texts = {
        full(name): schema_of(registry.message(full(name))).schema
        for name in reference_types()
        if full(name) in known
    }
    assert len(texts) >= len(reference_types()) - 1  # all but test_msgs/Builtins
    result = rwt_schemas(tmp_path, texts)
    changed = {alert["id"].removeprefix("schema-changed-") for alert in result["alerts"]}
    # a changed type is flagged under its own name and, met as a dependency, its short one
    assert {full(name) if "/msg/" not in name else name for name in changed} == set(
        CHANGED_SINCE_HUMBLE
    )
    # every other type, and every dependency, met its reference and was equal
    assert len(result["compared"]) > len(texts)
    reference = reference_types()
    for name, members in CHANGED_SINCE_HUMBLE.items():
        short = name.replace("/msg/", "/")
        assert not any(f" {member}" in reference[short] for member in members), name
        assert all(f" {member}" in texts[name] for member in members), name


def test_a_definition_out_of_its_files_order_is_flagged(tmp_path: Path) -> None:
    # the same members with the constants first (as rosbags keeps them) are "changed"
    registry = TypeRegistry(Dialect.ROS2)
    mtype = registry.message("actionlib_msgs/msg/GoalStatus")
    own, _, deps = schema_of(mtype).schema.partition("\n" + "=" * 80 + "\n")
    fields = [line for line in own.splitlines() if "=" not in line]
    constants = [line for line in own.splitlines() if "=" in line]
    reordered = "\n".join(constants + fields) + "\n" + "=" * 80 + "\n" + deps
    result = rwt_schemas(tmp_path, {"actionlib_msgs/msg/GoalStatus": reordered})
    assert [alert["id"] for alert in result["alerts"]] == [
        "schema-changed-actionlib_msgs/msg/GoalStatus"
    ]
    # while the order rwt writes (the file's, sources.declaration_orders()) is not
    assert "actionlib_msgs/msg/GoalStatus" in sources.declaration_orders()
    assert rwt_schemas(tmp_path, {mtype.name: schema_of(mtype).schema})["alerts"] == []
