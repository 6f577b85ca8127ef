"""The link's node keeps nothing of the entities it destroyed (a server whose clients churn).

rclpy's callback groups keep a weak reference to every entity added to them and never
drop one. The link's publishers come and go with the topics clients advertise and
leave, each with its QoS event handlers in the node's default group, so a server under
churn grew by a dead reference per publisher (the churn soak, docs/benchmarks.md, B26).
"""

from __future__ import annotations

import gc
from typing import TYPE_CHECKING

import pytest

from rwt_ros2.node import RosNode

from .support import skip_without_rclpy

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

pytestmark = [skip_without_rclpy(), pytest.mark.filterwarnings("ignore::DeprecationWarning")]

CYCLES = 50


@pytest.fixture
def node(ros_env: Path) -> Iterator[RosNode]:
    del ros_env
    made = RosNode("entities_test")
    made.start()
    try:
        yield made
    finally:
        made.close()


def _held(node: RosNode) -> int:
    groups = {id(g): g for g in (node.group, node.node.default_callback_group)}
    return sum(len(group.entities) for group in groups.values())


def test_publishers_and_services_that_come_and_go_leave_no_reference(node: RosNode) -> None:
    from std_msgs.msg import String  # noqa: PLC0415 (ROS 2 wheels: only when not skipped)
    from std_srvs.srv import SetBool  # noqa: PLC0415

    before = _held(node)
    for n in range(CYCLES):
        publisher = node.node.create_publisher(String, f"/churn/t{n % 8}", 10)
        publisher.publish(String(data="x"))
        node.node.destroy_publisher(publisher)
        service = node.node.create_service(
            SetBool, f"/churn/s{n % 8}", lambda _req, res: res, callback_group=node.group
        )
        node.node.destroy_service(service)
    del publisher, service
    gc.collect()
    assert _held(node) >= before + 2 * CYCLES  # rclpy's groups kept them all
    assert node.forget_destroyed() >= 2 * CYCLES
    assert _held(node) == before
    assert node.forget_destroyed() == 0


def test_live_entities_stay_in_their_groups(node: RosNode) -> None:
    from std_msgs.msg import String  # noqa: PLC0415 (ROS 2 wheels: only when not skipped)

    kept = node.node.create_subscription(
        String, "/kept", lambda _m: None, 10, callback_group=node.group
    )
    gone = node.node.create_publisher(String, "/gone", 10)
    node.node.destroy_publisher(gone)
    del gone
    gc.collect()
    assert node.forget_destroyed() >= 1
    assert node.group.has_entity(kept)
    node.node.destroy_subscription(kept)
