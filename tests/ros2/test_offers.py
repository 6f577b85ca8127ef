"""A service or action the link offers to ROS 2 answers its calls in flight before it goes.

The graph's provider goes while a ROS 2 call or goal waits for it: the graph
fails the call (D15) and the link answers the ROS 2 caller with the default
response (a goal: aborted). Here the link's executor is held while the
provider goes and the link's sweep retires the rclpy entity, the order a
loaded machine can produce: the answer must still reach the caller, and the
link must go on serving.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

import anyio
import pytest

from rwt_graph.async_calls import send_action_goal
from rwt_graph.graph import Graph
from rwt_graph.types.names import Dialect
from rwt_graph.types.registry import TypeRegistry
from rwt_ros2 import Ros2Options, open_ros2_link
from rwt_ros2.node import RosNode
from rwt_ros2.runtime import ament_interface_dirs
from rwt_transports.server import running_handlers
from tests.support.gates import CongestedGate

from .support import Peer, skip_without_rclpy, until

if TYPE_CHECKING:
    from collections.abc import Iterator
    from contextlib import AbstractContextManager
    from pathlib import Path

    from rwt_ros2.link import Ros2Link

pytestmark = [
    pytest.mark.anyio,
    skip_without_rclpy(),
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
]

SET_BOOL = "std_srvs/srv/SetBool"
FIBONACCI = "test_msgs/action/Fibonacci"


class HeldExecutor:
    """Holds the link's rclpy executor in one of its tasks until released."""

    def __init__(self, link: Ros2Link) -> None:
        self._link = link
        self.holding = threading.Event()
        self._release = threading.Event()

    def _hold(self) -> None:  # an executor task
        self.holding.set()
        self._release.wait(30)

    def __enter__(self) -> HeldExecutor:
        self._link.ros.executor.create_task(self._hold)
        return self

    def __exit__(self, *exc: object) -> None:
        self._release.set()


@pytest.fixture
def caller(ros_env: Path) -> Iterator[RosNode]:
    del ros_env
    node = RosNode("offers_caller")
    node.start()
    try:
        yield node
    finally:
        node.close()


class Holder:
    """A graph handler that never answers; counts the calls or goals it got."""

    def __init__(self) -> None:
        self.got = 0

    async def __call__(self, request: object, *context: object) -> Any:
        self.got += 1
        await anyio.sleep_forever()


def held(link: Ros2Link) -> AbstractContextManager[HeldExecutor]:
    return HeldExecutor(link)


async def test_a_call_in_flight_when_its_service_goes_gets_the_default_response(
    caller: RosNode,
) -> None:
    from std_srvs.srv import SetBool  # noqa: PLC0415

    graph = Graph()
    async with (
        running_handlers(graph) as handlers,
        open_ros2_link(graph, Ros2Options(node_name="offers_test")) as link,
    ):
        holder = Holder()
        local = graph.create_service("/o_switch", SET_BOOL, holder)
        client = caller.node.create_client(SetBool, "/o_switch")
        await until(client.service_is_ready, "the service on ROS 2")
        future = client.call_async(SetBool.Request(data=True))
        await until(lambda: holder.got == 1, "the call in the graph")
        with held(link) as executor:
            await until(executor.holding.is_set, "the executor held")
            local.close()  # the provider goes: the call fails (D15) while the executor waits
            await until(lambda: "/o_switch" not in link._servers, "the link's sweep")
        await until(future.done, "the ROS 2 caller's response")
        response = future.result()
        assert (response.success, response.message) == (False, "")
        await until(lambda: not client.service_is_ready(), "the service gone from ROS 2")

        # the link goes on serving
        graph.create_service("/o_again", SET_BOOL, lambda request: {"success": True})
        again = caller.node.create_client(SetBool, "/o_again")
        await until(again.service_is_ready, "the next service on ROS 2")
        second = again.call_async(SetBool.Request(data=True))
        await until(second.done, "the next call's response")
        assert second.result().success is True
        handlers.cancel_scope.cancel()


async def test_a_goal_in_flight_when_its_action_goes_is_aborted(caller: RosNode) -> None:
    from action_msgs.msg import GoalStatus  # noqa: PLC0415
    from rclpy.action import ActionClient  # noqa: PLC0415
    from test_msgs.action import Fibonacci  # noqa: PLC0415

    graph = Graph(TypeRegistry(Dialect.ROS2, ament_interface_dirs()))
    async with (
        running_handlers(graph) as handlers,
        open_ros2_link(graph, Ros2Options(node_name="offers_test")) as link,
    ):
        holder = Holder()
        local = graph.create_action_server("/o_fib", FIBONACCI, holder)
        client = ActionClient(caller.node, Fibonacci, "/o_fib")
        await until(client.server_is_ready, "the action on ROS 2")
        sent = client.send_goal_async(Fibonacci.Goal(order=3))
        await until(sent.done, "the goal accepted")
        result = sent.result().get_result_async()
        await until(lambda: holder.got == 1, "the goal in the graph")
        with held(link) as executor:
            await until(executor.holding.is_set, "the executor held")
            local.close()  # the action server goes: its goal ends (D15)
            await until(lambda: "/o_fib" not in link._action_servers, "the link's sweep")
        await until(result.done, "the ROS 2 goal's result")
        assert result.result().status == GoalStatus.STATUS_ABORTED
        await until(lambda: not client.server_is_ready(), "the action gone from ROS 2")
        handlers.cancel_scope.cancel()


async def test_a_callback_that_raises_leaves_the_node_spinning(
    caller: RosNode, caplog: pytest.LogCaptureFixture
) -> None:
    # rclpy raises a callback's error out of the executor's spin: one failure (an entity
    # destroyed under it, a peer's odd request) must not stop the link's ROS 2 side
    ticks: list[int] = []

    def fails() -> None:
        raise ValueError("one bad callback")

    caller.node.create_timer(0.01, fails)
    caller.node.create_timer(0.01, lambda: ticks.append(1))
    await until(lambda: len(ticks) >= 20, "the other callbacks going on")
    assert caller._thread.is_alive()
    failed = [r for r in caplog.records if "ros2_callback_failed" in r.getMessage()]
    assert len(failed) == 1  # once per episode, however often it repeats
    assert "one bad callback" in failed[0].getMessage()


async def test_a_ros2_goals_feedback_reaches_it_before_its_result_while_subscribers_congest(
    ros_env: Path,
) -> None:
    # A topic whose deliveries congest a subscriber is held back while other events go
    # on (TopicHolds); an action's feedback must not be: the goal's result would pass it
    # and end the goal, and the feedback behind would be lost.
    graph = Graph(TypeRegistry(Dialect.ROS2, ament_interface_dirs()))
    with Peer("fibonacci", "/o_served_fib", ros_env) as server:
        async with (
            running_handlers(graph) as handlers,
            open_ros2_link(graph, Ros2Options(node_name="offers_test")),
        ):
            await until(lambda: "/o_served_fib" in graph.actions.entries, "the ROS 2 action")
            graph.port.inflow = CongestedGate()  # type: ignore[misc]
            feedback: list[dict[str, Any]] = []
            with anyio.fail_after(30):
                outcome = await send_action_goal(
                    graph, "/o_served_fib", {"order": 4}, on_feedback=feedback.append
                )
            handlers.cancel_scope.cancel()
        del server
    assert outcome.result == {"sequence": [0, 1, 1, 2, 3]}
    assert [f["sequence"] for f in feedback] == [[0, 1, 1], [0, 1, 1, 2], [0, 1, 1, 2, 3]]
