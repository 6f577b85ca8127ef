"""The link's lanes to ROS 2 (rwt_ros2.outflow) and its publishers' depth, with real rclpy."""

from __future__ import annotations

import asyncio
import contextvars
import logging
from typing import TYPE_CHECKING, Any

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_graph.link import DEFAULT_DEPTH
from rwt_ros2 import Ros2Options, open_ros2_link
from rwt_ros2 import outflow as outflow_module
from rwt_ros2.graphview import MAX_PUBLISHER_DEPTH
from rwt_ros2.node import RosNode
from rwt_ros2.outflow import SAMPLE_OVERHEAD, Outflow

from .support import Peer, skip_without_rclpy

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

pytestmark = [
    pytest.mark.anyio,
    skip_without_rclpy(),
    # rclpy's generated packages import a deprecated module when first loaded here
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
]


@pytest.fixture
def publisher(ros_env: Path) -> Iterator[Any]:
    """An rclpy publisher of ``/lane`` (std_msgs/String, depth 10) on a spinning node."""
    ros = RosNode("outflow_test")
    ros.start()
    try:
        yield ros.node.create_publisher(_string(), "/lane", 10)
    finally:
        ros.close()


def _string() -> Any:
    from std_msgs.msg import String  # noqa: PLC0415

    return String


def _cdr(text: str) -> bytes:
    from rclpy.serialization import serialize_message  # noqa: PLC0415

    return bytes(serialize_message(_string()(data=text)))


async def _drained(lane: Any) -> None:
    with anyio.fail_after(20):
        while lane.waiting:
            await anyio.sleep(0.01)


async def test_a_lane_holds_its_samples_until_the_listener_matches(
    ros_env: Path, publisher: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the listener's process may take longer than MATCH_WAIT_S to start on a busy machine
    monkeypatch.setattr(outflow_module, "MATCH_WAIT_S", 60.0)
    async with anyio.create_task_group() as tasks:
        outflow = Outflow(tasks)
        lane = outflow.lane("/lane", publisher, expected=1)  # the sweep knew one listener
        samples = [_cdr(str(n)) for n in range(5)]
        for data in samples:
            lane.put(data)
        # nobody has matched yet: they wait, counted against the bound
        assert lane.waiting == 5
        assert outflow.queued_bytes == sum(len(d) + SAMPLE_OVERHEAD for d in samples)
        with Peer("count", "/lane", ros_env) as listener:
            await _drained(lane)
            heard = await anyio.to_thread.run_sync(listener.next)
            while heard["count"] < 5:
                heard = await anyio.to_thread.run_sync(listener.next)
        tasks.cancel_scope.cancel()
    assert heard == {"count": 5, "warm": 0, "ordered": True}
    assert outflow.queued_bytes == 0


async def test_a_lane_waits_for_a_match_within_its_bound(publisher: Any) -> None:
    async with anyio.create_task_group() as tasks:
        outflow = Outflow(tasks)
        lane = outflow.lane("/lane", publisher, expected=1)  # it never comes
        lane.put(_cdr("0"))
        assert lane.waiting == 1
        await _drained(lane)  # MATCH_WAIT_S later it went to whatever matched
        tasks.cancel_scope.cancel()
    assert outflow.queued_bytes == 0


async def test_a_sample_put_from_a_hand_over_callback_is_published(publisher: Any) -> None:
    # a ROS 2 sample handed over to a local subscriber that publishes on to ROS 2: the
    # hand-over's callback runs in no task, where the lane still starts its pump
    async with anyio.create_task_group() as tasks:
        outflow = Outflow(tasks)
        lane = outflow.lane("/lane", publisher, expected=1)  # it never comes
        loop = asyncio.get_running_loop()
        loop.call_soon(lane.put, _cdr("0"), context=contextvars.Context())
        with anyio.fail_after(5):
            while not lane.waiting:
                await anyio.sleep(0.01)
        await _drained(lane)
        tasks.cancel_scope.cancel()
    assert outflow.queued_bytes == 0


async def test_lanes_past_their_bound_drop_their_oldest_once_per_episode(
    publisher: Any, caplog: pytest.LogCaptureFixture
) -> None:
    size = len(_cdr("00")) + SAMPLE_OVERHEAD
    caplog.set_level(logging.WARNING, "rwt.ros2")
    async with anyio.create_task_group() as tasks:
        outflow = Outflow(tasks, max_bytes=4 * size)
        lane = outflow.lane("/lane", publisher, expected=1)
        for n in range(10):
            lane.put(_cdr(f"{n:02}"))
        assert lane.waiting == 4 and outflow.queued_bytes == 4 * size
        assert outflow.congested  # over half the bound: a publishing connection is held
        held = lane.take_held()
        tasks.cancel_scope.cancel()
    assert held == [_cdr(f"{n:02}") for n in range(6, 10)]  # the newest, in order
    lines = [r.getMessage() for r in caplog.records if "ros2_outflow_dropped" in r.getMessage()]
    assert len(lines) == 1 and "topic=/lane" in lines[0]


def _link_publisher_depth(link: Any, topic: str) -> int | None:
    """The history depth of the link's rclpy publisher of ``topic``, None if it has none."""
    for pub in link.ros.node.publishers:
        if pub.topic_name == topic:
            return int(pub.qos_profile.depth)
    return None


async def _depth_becomes(link: Any, topic: str, depth: int) -> int | None:
    with anyio.move_on_after(20):
        while _link_publisher_depth(link, topic) != depth:
            await anyio.sleep(0.05)
    return _link_publisher_depth(link, topic)


async def test_the_links_publisher_keeps_what_the_deepest_reliable_subscription_asks(
    ros_env: Path,
) -> None:
    # A web client's burst must wait in the link's publisher for the subscriptions
    # (as rosbridge's queue_size): a best-effort one asks for nothing, a reliable one
    # for its depth, unknown from Fast DDS for another node's, so the most
    # (MAX_PUBLISHER_DEPTH); the publisher is made again when a deeper one comes.
    from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: PLC0415

    graph = Graph()
    others = RosNode("depth_subscriber")
    others.start()
    try:
        best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
        others.node.create_subscription(_string(), "/deep", lambda m: None, best_effort)
        async with open_ros2_link(graph, Ros2Options(node_name="depth_test")) as link:
            with anyio.fail_after(20):  # the link knows the subscription
                while "/deep" not in dict(graph.topic_names_and_types()):
                    await anyio.sleep(0.05)
            graph.create_publisher("/deep", "std_msgs/msg/String").publish({"data": "0"})
            shallow = await _depth_becomes(link, "/deep", DEFAULT_DEPTH)
            reliable = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
            others.node.create_subscription(_string(), "/deep", lambda m: None, reliable)
            deep = await _depth_becomes(link, "/deep", MAX_PUBLISHER_DEPTH)
    finally:
        others.close()
    assert shallow == DEFAULT_DEPTH
    assert deep == MAX_PUBLISHER_DEPTH
