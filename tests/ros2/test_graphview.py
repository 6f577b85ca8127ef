"""A sweep of the ROS 2 graph while nodes leave under it (``rwt_ros2.graphview.snapshot``).

rcl lists the nodes, then is asked of each: a node that left in between makes rcl
raise (``RCLError: Failed to get action server names and type: error not set``, seen
in the suite when a test's peer exited during a sweep; the error ended the whole
server). The snapshot leaves such a node out, as if it had left before, and keeps
the others; a topic whose last endpoint left in between is left out the same way.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

pytest.importorskip("rclpy", reason="rclpy is not installed (the ros2 extra)")

from rclpy._rclpy_pybind11 import RCLError

from rwt_ros2.graphview import snapshot

GONE = "gone"


class _Handle:
    """The node's handle, a context manager as rclpy's is (``with node.handle``)."""

    def __enter__(self) -> _Handle:
        return self

    def __exit__(self, *_: object) -> None:
        return None

    def get_action_server_names_and_types_by_node(self, name: str, namespace: str) -> Any:
        if name == GONE:
            raise RCLError("Failed to get action server names and type: error not set")
        return [(f"/{name}/move", ["nav2_msgs/action/Move"])]


class _Node:
    """What rclpy's Node answers of a graph in which ``gone`` and ``/left`` just left."""

    handle = _Handle()

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        return [("rwt", "/"), ("kept", "/"), (GONE, "/")]

    def get_service_names_and_types_by_node(self, name: str, namespace: str) -> Any:
        return [(f"/{name}/reset", ["std_srvs/srv/Empty"])]

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        return [("/left", ["std_msgs/msg/String"]), ("/kept", ["std_msgs/msg/String"])]

    def get_publishers_info_by_topic(self, topic: str) -> list[Any]:
        if topic == "/left":
            raise RCLError("failed to get publishers: topic gone")
        return []

    def get_subscriptions_info_by_topic(self, topic: str) -> list[Any]:
        return []


def test_a_node_that_left_mid_sweep_is_left_out_and_the_rest_kept() -> None:
    ros = SimpleNamespace(node=_Node(), fqn="/rwt")
    graph = snapshot(ros)  # type: ignore[arg-type]
    assert graph.nodes == {"/kept"}
    assert graph.services == {("/kept", "/kept/reset"): "std_srvs/srv/Empty"}
    assert graph.actions == {("/kept", "/kept/move"): "nav2_msgs/action/Move"}
