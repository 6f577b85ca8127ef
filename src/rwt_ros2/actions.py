"""Actions across the link: ROS 2 action servers driven by rosbridge goals, and back.

``RosAction`` is the graph's provider of a ROS 2 action: a rosbridge
``send_action_goal`` (or an in-process one) becomes a goal of an rclpy
``ActionClient``; its feedback, its result with its status, and cancels travel
through it. Goals, feedback and results cross as CDR (``rclpy.serialization``
on rclpy's side, rwt's codec on the graph's). Every failure ends the goal with
a reason: no server, a refused goal, a server gone (the action leaves the
graph, which aborts its goals, D15), a missing Python package.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from rwt_protocol.errors import RwtError
from rwt_protocol.ports import GoalStatus

from .answer import Answer
from .codec import decode, encode
from .node import MAX_WAITING
from .runtime import interface_class

if TYPE_CHECKING:
    from rwt_graph.actions import Goal
    from rwt_graph.types.message import ActionType
    from rwt_protocol.ops import CancelActionGoal, SendActionGoal

    from .link import Ros2Link
    from .node import RosNode
    from .offers import Offer

__all__ = ["GoalOutcome", "RosAction", "serve_action_to_ros"]

logger = logging.getLogger("rwt.ros2")


class RosAction:
    """The graph's provider of the ROS 2 action ``name`` (see the module text).

    Args:
        link: the link.
        client: the participant standing for the ROS 2 action server.
        name: the action's name.
        actiontype: its type in the graph's registry.
    """

    def __init__(self, link: Ros2Link, client: str, name: str, actiontype: ActionType) -> None:
        self._link = link
        self._client = client
        self._name = name
        self._actiontype = actiontype
        self._ros_type: Any = None
        self._action_client: Any = None
        self._handles: dict[str, Any] = {}  # goal id -> rclpy ClientGoalHandle
        self._cancelled: set[str] = set()  # canceled before the server accepted
        # never held back behind a congested subscriber: the goal's result would pass it
        self._feedback_topic = name + "/_action/feedback"
        link.handoff.never_held.add(self._feedback_topic)

    def _goal(self, goal_id: str) -> Goal | None:
        entry = self._link.graph.actions.entries.get(self._name)
        if entry is None or entry.owner != self._client:
            return None
        return entry.goals.get(goal_id)

    def _fail(self, goal_id: str, reason: str) -> None:
        self._handles.pop(goal_id, None)
        goal = self._goal(goal_id)
        if goal is not None:
            goal.finish(GoalStatus.ABORTED, False, f"action {self._name}: {reason}")

    def on_action_goal(self, goal: SendActionGoal) -> None:
        """Send a graph caller's goal (``args`` in the internal form) to the ROS 2 server."""
        from rclpy.action.client import ActionClient  # noqa: PLC0415
        from rclpy.serialization import deserialize_message  # noqa: PLC0415

        link = self._link
        goal_id, args = str(goal.id), goal.args
        if self._action_client is None:
            try:
                self._ros_type = interface_class(self._actiontype.name)
            except RwtError as exc:
                self._fail(goal_id, str(exc))
                return
            self._action_client = ActionClient(
                link.ros.node, self._ros_type, self._name, callback_group=link.ros.group
            )
        if not self._action_client.server_is_ready():
            self._fail(goal_id, "no ROS 2 action server answers it")
            return
        try:
            data = encode(link.graph.registry, self._actiontype.goal, args)
            goal_msg = deserialize_message(data, self._ros_type.Goal)
        except Exception as exc:  # rclpy refuses what rosbags wrote: a type mismatch
            self._fail(goal_id, f"goal refused: {exc}")
            return

        def on_feedback(message: Any) -> None:  # an executor thread
            from rclpy.serialization import serialize_message  # noqa: PLC0415

            data = serialize_message(message.feedback)
            link.handoff.put(
                self._feedback, goal_id, data, size=len(data), topic=self._feedback_topic
            )

        future = self._action_client.send_goal_async(goal_msg, feedback_callback=on_feedback)
        future.add_done_callback(lambda f: link.handoff.put(self._accepted, goal_id, f))

    def _feedback(self, goal_id: str, data: bytes) -> None:
        goal = self._goal(goal_id)
        if goal is None:
            return
        try:
            goal.forward_feedback(
                decode(self._link.graph.registry, self._actiontype.feedback, data)
            )
        except RwtError as exc:
            self._link.episodes.log(
                logging.WARNING,
                f"feedback:{self._name}",
                "event=ros2_bad_feedback action=%s reason=%r",
                self._name,
                str(exc),
            )

    def _accepted(self, goal_id: str, future: Any) -> None:
        try:
            handle = future.result()
        except Exception as exc:  # the request failed (the server went meanwhile)
            self._fail(goal_id, f"goal not sent: {exc}")
            return
        if handle is None or not handle.accepted:
            self._fail(goal_id, "the ROS 2 action server rejected the goal")
            return
        if self._goal(goal_id) is None:  # the caller went meanwhile
            handle.cancel_goal_async()
            return
        self._handles[goal_id] = handle
        if goal_id in self._cancelled:
            self._cancelled.discard(goal_id)
            handle.cancel_goal_async()
        result = handle.get_result_async()
        result.add_done_callback(lambda f: self._link.handoff.put(self._result, goal_id, f))

    def _result(self, goal_id: str, future: Any) -> None:
        from rclpy.serialization import serialize_message  # noqa: PLC0415

        self._handles.pop(goal_id, None)
        goal = self._goal(goal_id)
        if goal is None:
            return
        try:
            response = future.result()
            values = decode(
                self._link.graph.registry,
                self._actiontype.result,
                serialize_message(response.result),
            )
            status = GoalStatus(response.status)
        except Exception as exc:  # no result (the server went), or one that does not decode
            self._fail(goal_id, f"no result: {exc}")
            return
        goal.finish(status, True, values)

    def on_action_cancel(self, cancel: CancelActionGoal) -> None:
        """Ask the ROS 2 server to cancel the goal (once it has accepted it)."""
        goal_id = str(cancel.id)
        handle = self._handles.get(goal_id)
        if handle is None:
            self._cancelled.add(goal_id)
        else:
            handle.cancel_goal_async()

    def on_action_lost(self, action: str, reason: str) -> None:
        """A local provider replaced the ROS 2 one in the graph; the ROS 2 one lives on."""
        logger.info("event=ros2_action_shadowed action=%s reason=%r", action, reason)

    def close(self) -> None:
        """Destroy the rclpy action client."""
        self._link.handoff.never_held.discard(self._feedback_topic)
        if self._action_client is not None:
            self._action_client.destroy()
            self._action_client = None


class GoalOutcome(Answer):
    """How a graph goal started for a ROS 2 client ended, awaited by its execute coroutine.

    Attributes:
        status: the goal's final status (ABORTED until told otherwise).
        result: the result's CDR when the graph answered with one.
        reason: why it failed, otherwise.
        handle: the graph's ``GoalHandle`` (set on the event loop).
        cancel_sent: whether the ROS 2 client's cancel was forwarded.
    """

    def __init__(self, ros: RosNode) -> None:
        super().__init__(ros)
        self.status = GoalStatus.ABORTED
        self.result: bytes | None = None
        self.reason = ""
        self.handle: Any = None
        self.cancel_sent = False

    def _settle(self, ok: bool, value: object, *detail: object) -> None:
        """``value``: the result's CDR when ``ok``, else the reason; ``detail``: the status."""
        super()._settle(ok, value)
        status = detail[0] if detail else GoalStatus.ABORTED
        self.status = status if isinstance(status, GoalStatus) else GoalStatus.ABORTED
        if ok and isinstance(value, bytes):
            self.result = value
        else:
            self.reason = str(value)


def _end(link: Ros2Link, name: str, ros_type: Any, goal_handle: Any, outcome: GoalOutcome) -> Any:
    """End the ROS 2 goal as the graph's ended; its result message."""
    from rclpy.serialization import deserialize_message  # noqa: PLC0415

    if outcome.result is not None:
        result = deserialize_message(outcome.result, ros_type.Result)
    else:
        result = ros_type.Result()
        link.episodes.log(
            logging.WARNING,
            f"goal:{name}",
            "event=ros2_goal_failed action=%s reason=%r",
            name,
            outcome.reason,
        )
    if outcome.status is GoalStatus.SUCCEEDED:
        goal_handle.succeed()
    elif outcome.status is GoalStatus.CANCELED:
        goal_handle.canceled()
    else:
        goal_handle.abort()
    return result


def _start_in_graph(
    link: Ros2Link,
    name: str,
    type_name: str,
    ros_type: Any,
    data: bytes,
    goal_handle: Any,
    outcome: GoalOutcome,
) -> None:
    """Send a ROS 2 client's goal (``data``: its CDR) in the graph (the event loop)."""
    from rclpy.serialization import deserialize_message  # noqa: PLC0415

    registry = link.graph.registry
    try:
        actiontype = registry.action(type_name)
        goal = decode(registry, actiontype.goal, data)

        def feedback(msg: dict[str, object]) -> None:
            payload = encode(registry, actiontype.feedback, msg)
            goal_handle.publish_feedback(deserialize_message(payload, ros_type.Feedback))

        def done(status: GoalStatus, result: bool, values: object) -> None:
            if result and isinstance(values, dict):
                outcome.set(True, encode(registry, actiontype.result, values), status)
            else:
                outcome.set(False, values, status)

        outcome.handle = link.graph.port.send_action_goal(link.caller, name, goal, done, feedback)
    except RwtError as exc:
        outcome.set(False, exc)


def serve_action_to_ros(
    link: Ros2Link, name: str, type_name: str, ros_type: Any, offer: Offer
) -> Any:
    """An rclpy action server offering the graph's action ``name`` to ROS 2 action clients.

    Each ROS 2 goal becomes a graph goal (``Graph.send_action_goal``) sent by the
    link's caller: its feedback is published to the ROS 2 client, its result
    and status end the ROS 2 goal, and a ROS 2 cancel request is forwarded. A
    goal the graph refuses, or whose provider goes, ends ABORTED (logged once
    per episode); so do goals in flight when the link stops. Each goal is
    inside ``offer`` while it runs, so the server outlives it (``offers``).
    """
    from rclpy.action.server import ActionServer, CancelResponse  # noqa: PLC0415
    from rclpy.serialization import serialize_message  # noqa: PLC0415

    def start(data: bytes, goal_handle: Any, outcome: GoalOutcome) -> None:  # the event loop
        _start_in_graph(link, name, type_name, ros_type, data, goal_handle, outcome)

    def cancel(outcome: GoalOutcome) -> None:  # the event loop
        if outcome.handle is not None:
            outcome.handle.request_cancel()

    running: dict[bytes, GoalOutcome] = {}  # goal id -> its outcome, while it runs

    async def execute(goal_handle: Any) -> Any:  # a task of the executor, until the goal ends
        offer.enter()
        try:
            return await run_goal(goal_handle)
        finally:
            offer.leave()

    async def run_goal(goal_handle: Any) -> Any:
        outcome = GoalOutcome(link.ros)
        if not link.ros.waiting.acquire(blocking=False):
            outcome.set(False, f"{MAX_WAITING} calls and goals from ROS 2 wait already")
            return _end(link, name, ros_type, goal_handle, outcome)
        goal_id = bytes(goal_handle.goal_id.uuid)
        link.pending_answers.add(outcome)
        running[goal_id] = outcome
        try:
            request = serialize_message(goal_handle.request)
            if link.handoff.put(start, request, goal_handle, outcome):
                await outcome
            else:
                outcome.set(False, "the ROS 2 link is stopping")
        finally:
            running.pop(goal_id, None)
            link.pending_answers.discard(outcome)
            link.ros.waiting.release()
        return _end(link, name, ros_type, goal_handle, outcome)

    def on_cancel(goal_handle: Any) -> Any:  # the executor: forwarded, then accepted
        outcome = running.get(bytes(goal_handle.goal_id.uuid))
        if outcome is not None and not outcome.cancel_sent:
            outcome.cancel_sent = True
            link.handoff.put(cancel, outcome)
        return CancelResponse.ACCEPT

    return ActionServer(
        link.ros.node,
        ros_type,
        name,
        execute,
        cancel_callback=on_cancel,
        callback_group=link.ros.group,
    )
