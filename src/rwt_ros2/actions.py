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
import threading
from typing import TYPE_CHECKING, Any

from rwt_protocol.errors import RwtError
from rwt_protocol.ports import GoalStatus

from .codec import decode, encode
from .node import MAX_WAITING
from .runtime import interface_class

if TYPE_CHECKING:
    from rwt_graph.actions import Goal
    from rwt_graph.types.message import ActionType

    from .link import Ros2Link

__all__ = ["CANCEL_POLL_S", "GoalOutcome", "RosAction", "serve_action_to_ros"]

logger = logging.getLogger("rwt.ros2")

CANCEL_POLL_S = 0.05
"""How often a goal from ROS 2 looks for its client's cancel request, seconds."""


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

    def on_action_goal(
        self, goal_id: str, action: str, action_type: str, args: dict[str, object]
    ) -> None:
        """Send a graph caller's goal (``args`` in the internal form) to the ROS 2 server."""
        from rclpy.action.client import ActionClient  # noqa: PLC0415
        from rclpy.serialization import deserialize_message  # noqa: PLC0415

        link = self._link
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
            link.handoff.put(self._feedback, goal_id, data, size=len(data), topic=self._name)

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

    def on_action_cancel(self, goal_id: str, action: str) -> None:
        """Ask the ROS 2 server to cancel the goal (once it has accepted it)."""
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
        if self._action_client is not None:
            self._action_client.destroy()
            self._action_client = None


class GoalOutcome:
    """How a graph goal started for a ROS 2 client ended, waited for on an executor thread."""

    def __init__(self) -> None:
        self.done = threading.Event()
        self.status = GoalStatus.ABORTED
        self.result: bytes | None = None
        self.reason = ""
        self.handle: Any = None  # the graph's GoalHandle, on the event loop
        self.cancel_sent = False

    def set(self, ok: bool, value: object, status: GoalStatus = GoalStatus.ABORTED) -> None:
        """End it: ``value`` is the result's CDR when ``ok``, else the reason."""
        if self.done.is_set():
            return
        self.status = status
        if ok and isinstance(value, bytes):
            self.result = value
        else:
            self.reason = str(value)
        self.done.set()


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


def serve_action_to_ros(link: Ros2Link, name: str, type_name: str, ros_type: Any) -> Any:
    """An rclpy action server offering the graph's action ``name`` to ROS 2 action clients.

    Each ROS 2 goal becomes a graph goal (``Graph.send_action_goal``) sent by the
    link's caller: its feedback is published to the ROS 2 client, its result
    and status end the ROS 2 goal, and a ROS 2 cancel request is forwarded. A
    goal the graph refuses, or whose provider goes, ends ABORTED (logged once
    per episode); so do goals in flight when the link stops.
    """
    from rclpy.action.server import ActionServer, CancelResponse  # noqa: PLC0415
    from rclpy.serialization import deserialize_message, serialize_message  # noqa: PLC0415

    registry = link.graph.registry

    def start(data: bytes, goal_handle: Any, outcome: GoalOutcome) -> None:  # the event loop
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

            outcome.handle = link.graph.send_action_goal(
                link.caller, name, type_name, goal, done, feedback
            )
        except RwtError as exc:
            outcome.set(False, exc)

    def cancel(outcome: GoalOutcome) -> None:  # the event loop
        if outcome.handle is not None:
            outcome.handle.request_cancel()

    def execute(goal_handle: Any) -> Any:  # an executor thread; blocks until the goal ends
        outcome = GoalOutcome()
        if not link.ros.waiting.acquire(blocking=False):
            outcome.set(False, f"{MAX_WAITING} calls and goals from ROS 2 wait already")
            return _end(link, name, ros_type, goal_handle, outcome)
        link.pending_answers.add(outcome)
        try:
            link.handoff.put(start, serialize_message(goal_handle.request), goal_handle, outcome)
            while not outcome.done.wait(CANCEL_POLL_S):
                if goal_handle.is_cancel_requested and not outcome.cancel_sent:
                    outcome.cancel_sent = True
                    link.handoff.put(cancel, outcome)
        finally:
            link.pending_answers.discard(outcome)
            link.ros.waiting.release()
        return _end(link, name, ros_type, goal_handle, outcome)

    return ActionServer(
        link.ros.node,
        ros_type,
        name,
        execute,
        cancel_callback=lambda _: CancelResponse.ACCEPT,
        callback_group=link.ros.group,
    )
