"""rosapi with real clients: roslibpy's and roslib's (roslibjs 2.x) helpers (REF §7.1, §7.2).

The server is examples/robot.py (a Python node `/rwt` with topics, the `/lights`
service, the `/fibonacci` action and parameters); the client publishes `/chatter`
and subscribes `/velocity`, then calls each rosapi helper. The assertions are on
what the helper hands to user code, in the client's own shapes.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from .client_harness import (
    REPO,
    Outcome,
    ServerProcess,
    advertise,
    api,
    connect,
    run_scenario,
    subscribe,
)

PY, JS = "roslibpy", "roslibjs"
ROS2_ROSAPI = [
    "action_feedback_details", "action_goal_details", "action_result_details",
    "action_servers", "action_type", "delete_param", "get_param", "get_param_names",
    "get_ros_version", "get_time", "has_param", "interfaces", "message_details",
    "node_details", "nodes", "publishers", "service_node", "service_providers",
    "service_request_details", "service_response_details", "service_type", "services",
    "services_for_type", "set_param", "subscribers", "topic_type", "topics",
    "topics_and_raw_types", "topics_for_type",
]  # fmt: skip
# The server offers tf2_web_republisher by default: /republish_tfs, /tf, /tf_static
# and the actionlib topics of /tf2_web_republisher (REF §7.3).
# /rwt has parameters, so it answers its ROS 2 parameter services (docs/agents.md)
PARAM_SERVICES = [
    f"/rwt/{name}"
    for name in (
        "describe_parameters", "get_parameter_types", "get_parameters", "list_parameters",
        "set_parameters", "set_parameters_atomically",
    )
]  # fmt: skip
SERVICES = [
    "/lights",
    "/republish_tfs",
    *(f"/rosapi/{name}" for name in ROS2_ROSAPI),
    *PARAM_SERVICES,
]
ACTIONLIB = ["cancel", "feedback", "goal", "result", "status"]
TOPICS = [
    "/chatter", "/client_count", "/cmd_vel", "/connected_clients", "/tf",
    *(f"/tf2_web_republisher/{name}" for name in ACTIONLIB), "/tf_static", "/velocity",
]  # fmt: skip
TYPES = [
    "std_msgs/msg/String",
    "std_msgs/msg/Int32",
    "geometry_msgs/msg/Twist",
    "rosbridge_msgs/msg/ConnectedClients",
    "tf2_msgs/msg/TFMessage",
    "actionlib_msgs/msg/GoalID",
    "tf2_web_republisher/msg/TFSubscriptionActionFeedback",
    "tf2_web_republisher/msg/TFSubscriptionActionGoal",
    "tf2_web_republisher/msg/TFSubscriptionActionResult",
    "actionlib_msgs/msg/GoalStatusArray",
    "tf2_msgs/msg/TFMessage",
    "geometry_msgs/msg/Twist",
]
NODES = ["/rosapi", "/rosbridge_websocket", "/rwt", "/rwt_client_1", "/tf2_web_republisher"]
ROBOT_NODE = {
    "subscribing": ["/cmd_vel"],
    "publishing": ["/velocity"],
    "services": ["/lights", *PARAM_SERVICES],
}
CLIENT_NODE = {"subscribing": ["/velocity"], "publishing": ["/chatter"], "services": []}
VECTOR3 = {
    "type": "geometry_msgs/Vector3",
    "fieldnames": ["x", "y", "z"],
    "fieldtypes": ["double", "double", "double"],
    "fieldarraylen": [-1, -1, -1],
    "examples": ["0.0", "0.0", "0.0"],
    "constnames": [],
    "constvalues": [],
}
TWIST_TYPEDEFS = [
    {
        "type": "geometry_msgs/Twist",
        "fieldnames": ["linear", "angular"],
        "fieldtypes": ["geometry_msgs/Vector3", "geometry_msgs/Vector3"],
        "fieldarraylen": [-1, -1],
        "examples": ["{}", "{}"],
        "constnames": [],
        "constvalues": [],
    },
    VECTOR3,
]


@pytest.fixture
def robot(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ServerProcess]:
    server = ServerProcess(tmp_path, cmd=[sys.executable, str(REPO / "examples" / "robot.py"), "0"])
    request.node._rwt_server = server
    try:
        yield server
    finally:
        server.stop()


def run(robot: ServerProcess, tmp_path: Path, client: str, calls: list[dict]) -> Outcome:
    steps = [
        connect("web"),
        advertise("web", "/chatter", "std_msgs/String"),
        subscribe("web", "/velocity", "geometry_msgs/Twist"),
        *calls,  # on the same connection, so after the advertise and the subscribe
    ]
    return run_scenario(robot.url, [("web", steps)], {"web": client}, tmp_path)


def test_roslibpy_rosapi_helpers(robot: ServerProcess, tmp_path: Path) -> None:
    def call(name: str, method: str, *args: object) -> dict:
        return api("web", name, method, *args, blocking=True)

    outcome = run(
        robot,
        tmp_path,
        PY,
        [
            call("topics", "get_topics"),
            call("topic_type", "get_topic_type", "/velocity"),
            call("services", "get_services"),
            call("nodes", "get_nodes"),
            call("robot_node", "get_node_details", "/rwt"),
            call("client_node", "get_node_details", "/rwt_client_1"),
            call("details", "get_message_details", "geometry_msgs/Twist"),
            api("web", "action_servers", "get_action_servers"),  # has no blocking form
            call("params", "get_params"),
            call("speed", "get_param", "/rwt:max_speed"),
            call("set", "set_param", "/rwt:max_speed", 2.5),
            call("speed_after", "get_param", "/rwt:max_speed"),
            call("delete", "delete_param", "/rwt:name"),
            call("params_after", "get_params"),
            call("deleted", "get_param", "/rwt:name"),
            call("time", "get_time"),
        ],
    )
    assert outcome.ok("topics") == TOPICS
    assert outcome.ok("topic_type") == "geometry_msgs/msg/Twist"
    assert outcome.ok("services") == SERVICES
    assert outcome.ok("nodes") == NODES
    assert outcome.ok("robot_node") == ROBOT_NODE
    assert outcome.ok("client_node") == CLIENT_NODE
    assert outcome.ok("details") == {"typedefs": TWIST_TYPEDEFS}
    assert outcome.ok("action_servers") == {
        "action_servers": ["/fibonacci", "/tf2_web_republisher"]
    }
    assert outcome.ok("params") == ["/rwt:max_speed", "/rwt:name"]
    assert outcome.ok("speed") == 1.0
    assert outcome.ok("speed_after") == 2.5
    assert outcome.ok("params_after") == ["/rwt:max_speed"]
    assert outcome.ok("deleted") is None  # roslibpy ignores `successful`; the value is null
    # roslibpy's get_time reads secs/nsecs (ROS 1 spelling); the ROS 2 answer carries both
    now = outcome.ok("time")
    assert set(now) == {"secs", "nsecs"} and now["secs"] > 1_600_000_000


@pytest.mark.node
def test_roslib_rosapi_helpers(robot: ServerProcess, tmp_path: Path) -> None:
    def call(name: str, method: str, *args: object) -> dict:
        return api("web", name, method, *args)

    outcome = run(
        robot,
        tmp_path,
        JS,
        [
            call("topics", "getTopics"),
            call("topic_type", "getTopicType", "/velocity"),
            call("topics_for_type", "getTopicsForType", "geometry_msgs/msg/Twist"),
            call("services", "getServices"),
            call("service_type", "getServiceType", "/lights"),
            call("nodes", "getNodes"),
            call("robot_node", "getNodeDetails", "/rwt"),
            call("client_node", "getNodeDetails", "/rwt_client_1"),
            call("details", "getMessageDetails", "geometry_msgs/Twist"),
            call("request", "getServiceRequestDetails", "std_srvs/SetBool"),
            call("action_servers", "getActionServers"),
            call("params", "getParams"),
            call("speed", "Param.get", "/rwt:max_speed"),
            call("set", "Param.set", "/rwt:max_speed", 2.5),
            call("speed_after", "Param.get", "/rwt:max_speed"),
            call("set_refused", "Param.set", "/ghost:x", 1),
            call("delete", "Param.delete", "/rwt:name"),
            call("params_after", "getParams"),
            call("deleted", "Param.get", "/rwt:name"),
        ],
    )
    assert outcome.ok("topics") == {"topics": TOPICS, "types": TYPES}
    assert outcome.ok("topic_type") == "geometry_msgs/msg/Twist"
    assert outcome.ok("topics_for_type") == ["/cmd_vel", "/velocity"]
    assert outcome.ok("services") == SERVICES
    assert outcome.ok("service_type") == "std_srvs/srv/SetBool"
    assert outcome.ok("nodes") == NODES
    assert outcome.ok("robot_node") == ROBOT_NODE
    assert outcome.ok("client_node") == CLIENT_NODE
    assert outcome.ok("details") == TWIST_TYPEDEFS
    assert outcome.ok("request")["typedefs"][0]["type"] == "std_srvs/SetBool_Request"
    assert outcome.ok("action_servers") == ["/fibonacci", "/tf2_web_republisher"]
    assert outcome.ok("params") == ["/rwt:max_speed", "/rwt:name"]
    assert outcome.ok("speed") == 1.0
    assert outcome.ok("set") == {"successful": True, "reason": ""}
    assert outcome.ok("speed_after") == 2.5
    assert outcome.calls["set_refused"] == {"error": "node /ghost does not exist"}
    assert outcome.ok("delete") == {"successful": True, "reason": ""}
    assert outcome.ok("params_after") == ["/rwt:max_speed"]
    assert outcome.calls["deleted"] == {"error": "parameter /rwt:name is not set"}
