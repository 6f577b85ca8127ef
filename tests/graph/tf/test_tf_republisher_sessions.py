"""The built-in tf2_web_republisher seen by clients: action, service, actionlib topics.

Sessions stand in for clients (the real ones run in tests/integration); the
republisher's sleep is released by the test one tick at a time (``Ticks``).
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from dataclasses import dataclass

import anyio
import pytest
from tests.conftest import FakeClock, Peer
from tests.tf_support import Ticks, tf_message, transform

from rwt_graph.graph import Graph
from rwt_graph.local import LocalPublisher
from rwt_graph.rosapi import install_rosapi
from rwt_graph.tf import TFRepublisher, install_tf_republisher
from rwt_graph.types import Dialect, TypeRegistry
from rwt_transports.server import RosbridgeServer, ServerConfig, running_handlers

pytestmark = pytest.mark.anyio

PKG = "tf2_web_republisher"
GOAL = {
    "source_frames": ["arm", "/camera"],
    "target_frame": "/base_link",
    "angular_thres": 0.1,
    "trans_thres": 0.05,
    "rate": 20.0,
}


@dataclass
class Robot:
    graph: Graph
    clock: FakeClock
    ticks: Ticks
    tf: TFRepublisher
    publisher: LocalPublisher

    def move_arm(self, x: float) -> None:
        self.publisher.publish(tf_message(transform("base_link", "arm", (x, 0.0, 0.0))))


async def robot_in(dialect: Dialect) -> AsyncIterator[Robot]:
    clock = FakeClock()
    graph = Graph(TypeRegistry(dialect), clock=clock)
    ticks = Ticks()
    tf = install_tf_republisher(graph, ticks.sleep)
    static = graph.create_publisher("/tf_static", "tf2_msgs/TFMessage", latch=True)
    static.publish(tf_message(transform("base_link", "camera", (0.0, 0.0, 1.0))))
    robot = Robot(graph, clock, ticks, tf, graph.create_publisher("/tf", "tf2_msgs/TFMessage"))
    robot.move_arm(0.0)
    async with running_handlers(graph) as tg:
        with anyio.fail_after(10):
            yield robot
        tg.cancel_scope.cancel()


@pytest.fixture
async def robot() -> AsyncIterator[Robot]:
    async for robot in robot_in(Dialect.ROS2):
        yield robot


@pytest.fixture(params=[Dialect.ROS1, Dialect.ROS2])
async def any_robot(request: pytest.FixtureRequest) -> AsyncIterator[Robot]:
    async for robot in robot_in(request.param):
        yield robot


def frames_of(transforms: object) -> dict[str, float]:
    assert isinstance(transforms, list)
    return {t["child_frame_id"]: t["transform"]["translation"]["x"] for t in transforms}


async def test_action_feedback_carries_changed_pairs_until_cancel(robot: Robot) -> None:
    client = Peer(robot.graph, "web")
    client.send(
        op="send_action_goal",
        action="/tf2_web_republisher",
        action_type="tf2_web_republisher_msgs/action/TFSubscription",
        args=GOAL,
        feedback=True,
        id="g",
    )
    await robot.ticks.settle()
    [first] = client.received()
    assert first["op"] == "action_feedback" and first["id"] == "g"
    assert frames_of(first["values"]["transforms"]) == {"arm": 0.0, "camera": 0.0}  # type: ignore[index]
    assert robot.ticks.periods == [pytest.approx(0.05)]  # 20 Hz

    robot.move_arm(0.03)  # under trans_thres
    await robot.ticks.tick()
    assert client.received() == []
    robot.move_arm(0.06)
    await robot.ticks.tick()
    [moved] = client.received()
    assert frames_of(moved["values"]["transforms"]) == {"arm": 0.06}  # type: ignore[index]

    client.send(op="cancel_action_goal", action="/tf2_web_republisher", id="g")
    await robot.ticks.tick()
    [result] = client.received()
    assert result["op"] == "action_result" and result["status"] == 5  # CANCELED
    assert robot.tf.active == 0


async def test_a_client_that_leaves_stops_its_goal(robot: Robot) -> None:
    client = Peer(robot.graph, "web")
    client.send(op="send_action_goal", action="/tf2_web_republisher", action_type="x/y", args=GOAL)
    await robot.ticks.settle()
    assert robot.tf.active == 1
    client.session.close()
    await robot.ticks.tick()
    assert robot.tf.active == 0


async def test_republish_tfs_serves_a_latched_topic_until_nobody_listens(robot: Robot) -> None:
    client = Peer(robot.graph, "py")
    timeout = {"secs": 2, "nsecs": 0}  # roslibpy sends the ROS 1 spelling
    client.send(op="call_service", service="/republish_tfs", args={**GOAL, "timeout": timeout})
    [response] = client.received()
    assert response["values"] == {"topic_name": "/tf_repub_0"} and response["result"] is True
    await robot.ticks.settle()
    assert ("/tf_repub_0", "tf2_web_republisher/msg/TFArray") in robot.graph.topic_names_and_types()

    client.send(op="subscribe", topic="/tf_repub_0", type="tf2_web_republisher/TFArray")
    await robot.ticks.tick()
    [first] = client.received()
    assert frames_of(first["msg"]["transforms"]) == {"arm": 0.0, "camera": 0.0}  # type: ignore[index]
    robot.move_arm(0.2)
    await robot.ticks.tick()
    assert frames_of(client.received()[0]["msg"]["transforms"]) == {"arm": 0.2}  # type: ignore[index]

    late = Peer(robot.graph, "late")  # latched: a late subscriber gets the last array
    late.send(op="subscribe", topic="/tf_repub_0")
    assert frames_of(late.received()[0]["msg"]["transforms"]) == {"arm": 0.2}  # type: ignore[index]

    client.send(op="unsubscribe", topic="/tf_repub_0")
    late.send(op="unsubscribe", topic="/tf_repub_0")
    robot.clock.now += 1.9
    await robot.ticks.tick()
    assert "/tf_repub_0" in robot.graph.topics
    robot.clock.now += 0.2
    await robot.ticks.tick()
    assert "/tf_repub_0" not in robot.graph.topics
    assert robot.tf.active == 0 and robot.ticks.sleeping == 0


async def test_republish_tfs_answers_whichever_package_name_a_caller_gives(robot: Robot) -> None:
    # roslibpy names tf2_web_republisher/RepublishTFs, ROS 2 ports name the others
    client = Peer(robot.graph, "c")
    for index, type_name in enumerate(
        [
            "tf2_web_republisher/RepublishTFs",
            "tf2_web_republisher_msgs/srv/RepublishTFs",
            "tf2_web_republisher_interfaces/RepublishTFs",
        ]
    ):
        client.send(op="call_service", service="/republish_tfs", type=type_name, args=GOAL)
        [response] = client.received()
        assert response["values"] == {"topic_name": f"/tf_repub_{index}"}, type_name


async def test_a_bad_request_fails_the_call_with_a_reason(robot: Robot) -> None:
    client = Peer(robot.graph, "c")
    args = {"source_frames": ["arm"]}
    client.send(op="call_service", service="/republish_tfs", args=args, id="x")
    [response] = client.received()
    assert response["result"] is False and "target_frame is empty" in str(response["values"])
    assert robot.tf.active == 0


async def test_requests_beyond_the_limit_are_refused(robot: Robot) -> None:
    robot.tf.max_active = 1
    client = Peer(robot.graph, "c")
    client.send(op="call_service", service="/republish_tfs", args=GOAL)
    client.send(op="call_service", service="/republish_tfs", args=GOAL)
    first, second = client.received()
    assert first["result"] is True
    assert second["result"] is False and "too many TF subscriptions" in str(second["values"])


async def test_transforms_published_by_a_client_feed_the_buffer(robot: Robot) -> None:
    client = Peer(robot.graph, "driver")
    client.send(
        op="publish",
        topic="/tf",
        msg=tf_message(transform("/arm", "/gripper", (0.5, 0.0, 0.0))),
    )
    found = robot.tf.buffer.lookup("base_link", "gripper")
    assert list(found.matrix[:3, 3]) == [0.5, 0.0, 0.0]


async def test_actionlib_topics_serve_a_roslibjs_tfclient_goal(any_robot: Robot) -> None:
    client = Peer(any_robot.graph, "web")
    ns = "/tf2_web_republisher"
    client.send(op="subscribe", topic=f"{ns}/feedback", type=f"{PKG}/TFSubscriptionActionFeedback")
    client.send(op="advertise", topic=f"{ns}/goal", type=f"{PKG}/TFSubscriptionActionGoal")
    client.send(op="advertise", topic=f"{ns}/cancel", type="actionlib_msgs/GoalID")
    goal_id = {"stamp": {"secs": 0, "nsecs": 0}, "id": "goal_1"}
    client.send(op="publish", topic=f"{ns}/goal", msg={"goal_id": goal_id, "goal": GOAL})
    await any_robot.ticks.settle()
    [feedback] = client.received()
    assert feedback["msg"]["status"]["goal_id"]["id"] == "goal_1"  # type: ignore[index]
    transforms = feedback["msg"]["feedback"]["transforms"]  # type: ignore[index]
    assert frames_of(transforms) == {"arm": 0.0, "camera": 0.0}
    ros1 = any_robot.graph.registry.dialect is Dialect.ROS1
    stamp = {"secs": 1, "nsecs": 0} if ros1 else {"sec": 1, "nanosec": 0}
    assert transforms[0]["header"]["stamp"] == stamp
    # sent unchecked, yet complete: checking what the client got changes nothing
    feedback_type = any_robot.graph.registry.message(f"{PKG}/TFSubscriptionActionFeedback")
    checked = feedback_type.from_json(feedback["msg"], now=0.0)
    assert checked.missing == () and checked.msg == feedback["msg"]

    client.send(op="subscribe", topic=f"{ns}/result", type=f"{PKG}/TFSubscriptionActionResult")
    client.send(op="publish", topic=f"{ns}/cancel", msg={"id": "goal_1"})
    await any_robot.ticks.tick()
    [result] = client.received()
    assert result["msg"]["status"]["status"] == 2  # type: ignore[index]  # PREEMPTED
    assert any_robot.tf.active == 0

    if ros1:  # rosapi lists a ROS 1 action server when its five topics exist
        install_rosapi(any_robot.graph)
        api = Peer(any_robot.graph, "api")
        api.send(op="call_service", service="/rosapi/action_servers", args={})
        [servers] = api.received()
        assert ns in servers["values"]["action_servers"]  # type: ignore[index]


async def test_actionlib_goals_nobody_reads_end_after_a_while(any_robot: Robot) -> None:
    client = Peer(any_robot.graph, "web")
    ns = "/tf2_web_republisher"
    client.send(op="subscribe", topic=f"{ns}/feedback", type=f"{PKG}/TFSubscriptionActionFeedback")
    client.send(op="advertise", topic=f"{ns}/goal", type=f"{PKG}/TFSubscriptionActionGoal")
    client.send(op="publish", topic=f"{ns}/goal", msg={"goal": GOAL})
    await any_robot.ticks.settle()
    assert any_robot.tf.active == 1
    client.session.close()  # gone without cancelling
    any_robot.clock.now += 2.5
    await any_robot.ticks.tick()
    await any_robot.ticks.tick()
    assert any_robot.tf.active == 0


async def test_without_tf_the_server_offers_none_of_it() -> None:
    server = RosbridgeServer(config=ServerConfig(tf=False))
    assert server.tf is None
    assert "/republish_tfs" not in server.graph.services.entries
    assert "/tf" not in server.graph.topics
    assert RosbridgeServer().tf is not None


async def test_closing_the_republisher_ends_its_loops_and_withdraws_it(robot: Robot) -> None:
    client = Peer(robot.graph, "web")
    client.send(op="send_action_goal", action="/tf2_web_republisher", action_type="t", args=GOAL)
    client.send(op="call_service", service="/republish_tfs", args=GOAL)
    await robot.ticks.settle()
    assert robot.tf.active == 2
    robot.tf.close()
    await robot.ticks.tick()
    assert robot.tf.active == 0 and robot.ticks.sleeping == 0
    assert "/republish_tfs" not in robot.graph.services.entries
    assert sorted(robot.graph.topics) == ["/tf", "/tf_static"]  # the robot's publishers
    assert not robot.graph.topics["/tf"].subscribers
