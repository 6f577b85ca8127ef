"""rosapi introspection through client sessions, ROS 2 shapes (REF §7.1, §7.2; D5, D26)."""

from __future__ import annotations

import pytest

from rwt_graph.graph import Graph
from rwt_graph.rosapi import Visibility, install_rosapi
from rwt_protocol.errors import GraphError
from tests.conftest import FakeClock, Peer
from tests.session.rosapi_support import call, call_raw, connect

FIB = "example_interfaces/action/Fibonacci"


async def _never(goal: dict[str, object], context: object) -> dict[str, object]:
    raise AssertionError("no goal is sent in these tests")


@pytest.fixture
def robot(graph: Graph) -> Graph:
    """A graph with rosapi, a robot node in Python and one client that uses it."""
    install_rosapi(graph)
    graph.create_publisher("/odom", "nav_msgs/msg/Odometry", node="/base")
    graph.create_subscription("/cmd_vel", lambda msg: None, "geometry_msgs/Twist", node="/base")
    graph.create_service("/reset", "std_srvs/srv/Empty", lambda request: {}, node="/base")
    graph.create_action_server("/fibonacci", FIB, _never, node="/base")
    graph.create_publisher("/base/_hidden", "std_msgs/msg/Int32", node="/base")
    return graph


@pytest.fixture
def web(robot: Graph) -> Peer:
    """A client that publishes /cmd_vel, subscribes /odom and provides /set_light."""
    peer = connect(robot, "web")
    peer.send(op="advertise", topic="cmd_vel", type="geometry_msgs/Twist")
    peer.send(op="subscribe", topic="/odom")
    peer.send(op="advertise_service", service="/set_light", type="std_srvs/SetBool")
    peer.received()
    return peer


def test_topics_lists_every_visible_topic_with_its_canonical_type(web: Peer) -> None:
    assert call(web, "/rosapi/topics") == {
        "topics": ["/cmd_vel", "/odom"],
        "types": ["geometry_msgs/msg/Twist", "nav_msgs/msg/Odometry"],
    }


def test_relative_rosapi_names_resolve_and_the_reply_keeps_the_spelling(web: Peer) -> None:
    web.send(op="call_service", service="rosapi/topics", id="call_service:rosapi/topics:1")
    [reply] = web.received()
    assert reply["service"] == "rosapi/topics"
    assert reply["id"] == "call_service:rosapi/topics:1"
    assert reply["values"]["topics"] == ["/cmd_vel", "/odom"]  # type: ignore[index]


@pytest.mark.parametrize("spelling", ["geometry_msgs/msg/Twist", "geometry_msgs/Twist"])
def test_topics_for_type_takes_either_spelling(web: Peer, spelling: str) -> None:
    assert call(web, "/rosapi/topics_for_type", type=spelling) == {"topics": ["/cmd_vel"]}
    assert call(web, "/rosapi/topics_for_type", type="not a type") == {"topics": []}


def test_topics_and_raw_types_carry_the_gendeps_full_text(web: Peer) -> None:
    values = call(web, "/rosapi/topics_and_raw_types")
    assert values["topics"] == ["/cmd_vel", "/odom"]
    assert values["types"] == ["geometry_msgs/msg/Twist", "nav_msgs/msg/Odometry"]
    twist, odometry = values["typedefs_full_text"]
    assert twist == (
        "geometry_msgs/Vector3 linear\n"
        "geometry_msgs/Vector3 angular\n"
        f"{'=' * 80}\n"
        "MSG: geometry_msgs/Vector3\n"
        "float64 x\nfloat64 y\nfloat64 z\n"
    )
    assert odometry.count("=" * 80) == 9  # Header, Time, PoseWithCovariance, Pose, ...
    assert "\nMSG: geometry_msgs/TwistWithCovariance\n" in odometry


def test_services_and_their_types(web: Peer) -> None:
    services = call(web, "/rosapi/services")["services"]
    assert isinstance(services, list)
    assert {"/reset", "/set_light", "/rosapi/topics", "/rosapi/get_param"} <= set(services)
    assert services == sorted(services)
    assert call(web, "/rosapi/services_for_type", type="std_srvs/SetBool") == {
        "services": ["/set_light"]
    }
    assert call(web, "/rosapi/service_type", service="set_light") == {
        "type": "std_srvs/srv/SetBool"
    }
    assert call(web, "/rosapi/service_type", service="/nothing") == {"type": ""}
    assert call(web, "/rosapi/topic_type", topic="odom") == {"type": "nav_msgs/msg/Odometry"}
    assert call(web, "/rosapi/topic_type", topic="/nothing") == {"type": ""}


def test_nodes_are_python_nodes_rosapi_and_each_client(robot: Graph, web: Peer) -> None:
    idle = connect(robot, "idle")
    assert call(web, "/rosapi/nodes") == {
        "nodes": ["/base", "/rosapi", "/rwt_client_1", "/rwt_client_2"]
    }
    idle.session.close()
    assert call(web, "/rosapi/nodes")["nodes"] == ["/base", "/rosapi", "/rwt_client_1"]


def test_node_details_of_a_client_and_of_a_python_node(web: Peer) -> None:
    assert call(web, "/rosapi/node_details", node="/rwt_client_1") == {
        "subscribing": ["/odom"],
        "publishing": ["/cmd_vel"],
        "services": ["/set_light"],
    }
    assert call(web, "/rosapi/node_details", node="base") == {
        "subscribing": ["/cmd_vel"],
        "publishing": ["/odom"],  # hidden names stay out, as in ros2 node info
        "services": ["/reset"],
    }
    reply = call_raw(web, "/rosapi/node_details", node="/ghost")
    assert reply["result"] is False
    assert reply["values"] == "service /rosapi/node_details failed: node /ghost does not exist"


def test_publishers_subscribers_and_service_providers_are_node_names(web: Peer) -> None:
    assert call(web, "/rosapi/publishers", topic="/cmd_vel") == {"publishers": ["/rwt_client_1"]}
    assert call(web, "/rosapi/subscribers", topic="cmd_vel") == {"subscribers": ["/base"]}
    assert call(web, "/rosapi/subscribers", topic="/none") == {"subscribers": []}
    assert call(web, "/rosapi/service_providers", service="std_srvs/srv/Empty") == {
        "providers": ["/base"]
    }
    assert call(web, "/rosapi/service_node", service="/set_light") == {"node": "/rwt_client_1"}
    assert call(web, "/rosapi/service_node", service="/none") == {"node": ""}


def test_action_servers_of_python_and_of_clients(robot: Graph, web: Peer) -> None:
    web.send(op="advertise_action", action="/dock", type=FIB)
    assert call(web, "/rosapi/action_servers") == {"action_servers": ["/dock", "/fibonacci"]}
    assert call(web, "/rosapi/action_type", action="fibonacci") == {"type": FIB}
    assert call(web, "/rosapi/action_type", action="/none") == {"type": ""}


def test_a_leaving_client_takes_its_node_and_names_with_it(robot: Graph, web: Peer) -> None:
    other = connect(robot, "other")
    web.session.close()
    assert call(other, "/rosapi/topics")["topics"] == ["/cmd_vel", "/odom"]  # /base has both
    assert call(other, "/rosapi/publishers", topic="/cmd_vel") == {"publishers": []}
    assert "/set_light" not in call(other, "/rosapi/services")["services"]
    assert "/rwt_client_1" not in call(other, "/rosapi/nodes")["nodes"]


def test_closing_python_handles_removes_their_node(graph: Graph) -> None:
    install_rosapi(graph)
    publisher = graph.create_publisher("/p", "std_msgs/msg/String", node="/talker")
    client = connect(graph, "c")
    assert "/talker" in call(client, "/rosapi/nodes")["nodes"]
    publisher.close()
    assert call(client, "/rosapi/nodes")["nodes"] == ["/rosapi", "/rwt_client_1"]


def test_time_version_and_interfaces(web: Peer, clock: FakeClock) -> None:
    clock.epoch = 1_700_000_123.5
    stamp = {"sec": 1_700_000_123, "nanosec": 500_000_000}
    # secs/nsecs too: roslibpy's get_time reads only those (REF §7.2)
    assert call(web, "/rosapi/get_time") == {
        "time": {**stamp, "secs": stamp["sec"], "nsecs": stamp["nanosec"]}
    }
    assert call(web, "/rosapi/get_ros_version") == {"version": 2, "distro": "jazzy"}
    interfaces = call(web, "/rosapi/interfaces")["interfaces"]
    assert isinstance(interfaces, list)
    assert {"std_msgs/msg/String", "std_srvs/srv/SetBool", FIB} <= set(interfaces)


def test_get_ros_version_says_the_graphs_distribution_at_each_call(graph: Graph, web: Peer) -> None:
    # a link to a running ROS sets its distribution while it is open (docs/ros2.md)
    graph.ros_distro = "kilted"
    assert call(web, "/rosapi/get_ros_version") == {"version": 2, "distro": "kilted"}


def test_visibility_hides_names_per_calling_client(graph: Graph) -> None:
    def visibility(client: str) -> Visibility:
        if client != "guest":
            return Visibility()
        return Visibility(
            topics=lambda name: name != "/secret",
            services=lambda name: name.startswith("/rosapi/"),
            params=lambda name: name.endswith(":public"),
            actions=lambda name: False,
        )

    install_rosapi(graph, visibility=visibility)
    graph.create_publisher("/secret", "std_msgs/msg/String", node="/robot")
    graph.create_publisher("/open", "std_msgs/msg/String", node="/robot")
    graph.create_service("/private", "std_srvs/srv/Empty", lambda request: {}, node="/robot")
    graph.create_action_server("/fibonacci", FIB, _never, node="/robot")
    graph.params.declare("/robot", {"public": 1, "secret": 2})
    guest, admin = connect(graph, "guest"), connect(graph, "admin")

    assert call(guest, "/rosapi/topics")["topics"] == ["/open"]
    assert call(guest, "/rosapi/topic_type", topic="/secret") == {"type": ""}
    assert call(guest, "/rosapi/publishers", topic="/secret") == {"publishers": []}
    assert "/private" not in call(guest, "/rosapi/services")["services"]
    assert call(guest, "/rosapi/service_node", service="/private") == {"node": ""}
    assert call(guest, "/rosapi/node_details", node="/robot") == {
        "subscribing": [],
        "publishing": ["/open"],
        "services": [],
    }
    assert call(guest, "/rosapi/action_servers") == {"action_servers": []}
    assert call(guest, "/rosapi/get_param_names") == {"names": ["/robot:public"]}
    hidden = call(guest, "/rosapi/get_param", name="/robot:secret")
    assert hidden["successful"] is False and hidden["value"] == "null"
    assert call(guest, "/rosapi/has_param", name="/robot:secret") == {"exists": False}

    assert call(admin, "/rosapi/topics")["topics"] == ["/open", "/secret"]
    assert call(admin, "/rosapi/action_servers") == {"action_servers": ["/fibonacci"]}
    assert call(admin, "/rosapi/get_param_names")["names"] == ["/robot:public", "/robot:secret"]


@pytest.mark.parametrize("node", ["9lives", "/a b", "/ok/-no", ""])
def test_bad_node_names_are_refused_and_leave_nothing_behind(graph: Graph, node: str) -> None:
    with pytest.raises(GraphError, match="invalid node name"):
        graph.create_publisher("/p", "std_msgs/msg/String", node=node)
    assert graph.topics == {} and graph.nodes.names() == set()


def test_a_failed_registration_leaves_no_node(graph: Graph) -> None:
    with pytest.raises(GraphError):
        graph.create_service("/s", "std_srvs/srv/Nope", lambda request: {}, node="/x")
    graph.create_publisher("/p", "std_msgs/msg/String")
    with pytest.raises(GraphError):
        graph.create_subscription("/p", lambda msg: None, "std_msgs/msg/Int32", node="/y")
    assert graph.nodes.names() == {"/rwt"}
