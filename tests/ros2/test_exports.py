"""The ROS 2 link shares the graph's local entities from its change feed (rwt_graph.exports).

An rclpy node watches the ROS 2 graph while Python code adds local entities to a
linked graph and closes them again; the link's outward side holds only what is
local, never what it mirrored in from ROS 2 (no echo).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pytest

from rwt_graph.feed import EntityKind
from rwt_graph.graph import Graph
from rwt_ros2 import Ros2Options, open_ros2_link
from rwt_ros2.node import RosNode

from .support import skip_without_rclpy, until

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = [
    pytest.mark.anyio,
    skip_without_rclpy(),
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
]

STRING = "std_msgs/msg/String"
TRIGGER = "std_srvs/srv/Trigger"


def seen(watcher: RosNode) -> set[tuple[str, str]]:
    """What the ROS 2 graph shows of the link's node: (kind, name)."""
    node = watcher.node
    found = {
        ("service", name)
        for name, node_name, _ in _services(node)
        if node_name == "exports_test" and name.startswith("/x_")
    }
    for topic in ("/x_odom", "/x_cmd"):
        if any(i.node_name == "exports_test" for i in node.get_publishers_info_by_topic(topic)):
            found.add(("publisher", topic))
        if any(i.node_name == "exports_test" for i in node.get_subscriptions_info_by_topic(topic)):
            found.add(("subscription", topic))
    return found


def _services(node: Any) -> list[tuple[str, str, list[str]]]:
    return [
        (name, node_name, types)
        for node_name, namespace in node.get_node_names_and_namespaces()
        if node_name == "exports_test"
        for name, types in node.get_service_names_and_types_by_node(node_name, namespace)
    ]


async def test_local_entities_reach_ros2_and_leave_it_and_the_mirrored_do_not_echo(
    ros_env: Path,
) -> None:
    from std_msgs.msg import String  # noqa: PLC0415

    graph = Graph()
    watcher = RosNode("exports_watcher")
    watcher.start()
    try:
        watcher.node.create_publisher(String, "/x_far", 10)  # mirrored in, never back out
        async with open_ros2_link(graph, Ros2Options(node_name="exports_test")) as link:
            await until(lambda: "/x_far" in graph.topics, "the watcher's publisher mirrored")
            handles: list[Any] = [
                graph.create_publisher("/x_odom", STRING, node="/robot"),
                graph.create_subscription("/x_cmd", lambda msg: None, STRING, node="/robot"),
                graph.create_service("/x_reset", TRIGGER, lambda request: {}, node="/robot"),
            ]
            expected = {
                ("publisher", "/x_odom"),
                ("subscription", "/x_cmd"),
                ("service", "/x_reset"),
            }
            await until(lambda: seen(watcher) == expected, "the local entities on ROS 2")
            shared = {
                name for entities in link.outward.current.values() for (_, _, name) in entities
            }
            assert "/x_far" not in shared
            assert {"/x_odom", "/x_cmd", "/x_reset"} <= shared
            assert not any(
                link.rules.ours(client)
                for entities in link.outward.current.values()
                for (_, client, _) in entities
            )
            assert link.outward.owners(EntityKind.SERVICE)["/x_reset"].node == "/robot"
            for handle in handles:
                handle.close()
            await until(lambda: not seen(watcher), "the local entities gone from ROS 2")
    finally:
        watcher.close()
