"""The actionlib face of the TF republisher, for roslibjs ``TFClient`` (REF §7.3).

roslibjs ``TFClient`` speaks actionlib over plain topics: it publishes
``TFSubscriptionActionGoal`` messages on ``/tf2_web_republisher/goal`` and
``actionlib_msgs/GoalID`` on ``/tf2_web_republisher/cancel``, and reads
``TFSubscriptionActionFeedback`` from ``/tf2_web_republisher/feedback``, matching
feedback to its goal by ``status.goal_id.id``. This module serves those topics
(plus ``status`` and ``result``, so ROS 1 rosapi lists the action server). It does
so in the ROS 2 dialect too: actionlib is ROS 1, but roslib 2.x's ``TFClient``
(the one ros3djs uses) speaks nothing else, and a ROS-free server can offer both.

Topics carry no sender, so a goal whose client left without cancelling cannot be
told apart from a live one; a goal therefore also ends once ``feedback`` has had
no subscriber for ``ORPHAN_TIMEOUT_S``.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rwt_protocol.errors import RwtError

from ..ratelog import EpisodeLog
from .buffer import TFError

if TYPE_CHECKING:
    from collections.abc import Callable

    from .install import TFRepublisher
    from .republisher import TFSubscription

__all__ = ["ORPHAN_TIMEOUT_S", "ActionlibServer"]

logger = logging.getLogger("rwt.tf")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

Message = dict[str, object]

#: A goal ends when its feedback topic has had no subscriber this long (seconds).
ORPHAN_TIMEOUT_S = 2.0
#: actionlib_msgs/GoalStatus codes used here.
ACTIVE, PREEMPTED, REJECTED = 1, 2, 5

_NS = "/tf2_web_republisher"
_PKG = "tf2_web_republisher"


@dataclass(eq=False)
class _Goal:
    goal_id: Message
    canceled: bool = False


class ActionlibServer:
    """The five actionlib topics of ``/tf2_web_republisher``, served by a ``TFRepublisher``."""

    def __init__(self, republisher: TFRepublisher) -> None:
        self.republisher = republisher
        self.goals: dict[str, _Goal] = {}
        self._ids = itertools.count(1)

    def start(self) -> Callable[[], None]:
        """Create the topics; returns a function that removes them again.

        Raises:
            GraphError: a topic is in use with another type.
        """
        graph, node = self.republisher.graph, self.republisher.node
        self.feedback = graph.create_publisher(
            f"{_NS}/feedback", f"{_PKG}/TFSubscriptionActionFeedback", node=node, reserved=True
        )
        self.status = graph.create_publisher(
            f"{_NS}/status", "actionlib_msgs/GoalStatusArray", node=node, reserved=True
        )
        self.result = graph.create_publisher(
            f"{_NS}/result", f"{_PKG}/TFSubscriptionActionResult", node=node, reserved=True
        )
        goal = graph.create_subscription(
            f"{_NS}/goal", self.on_goal, f"{_PKG}/TFSubscriptionActionGoal", node=node
        )
        cancel = graph.create_subscription(
            f"{_NS}/cancel", self.on_cancel, "actionlib_msgs/GoalID", node=node
        )
        handles = (goal, cancel, self.feedback, self.status, self.result)

        def close() -> None:
            for goal_state in self.goals.values():
                goal_state.canceled = True
            for handle in handles:
                handle.close()

        return close

    def on_goal(self, msg: Message) -> None:
        """Start ticking a goal; a goal id already running is replaced."""
        goal_id = msg["goal_id"]
        assert isinstance(goal_id, dict)
        key = str(goal_id["id"]) or f"rwt_goal_{next(self._ids)}"
        goal_msg = msg["goal"]
        assert isinstance(goal_msg, dict)
        try:
            subscription = self.republisher.subscription(goal_msg)
            spawn = self.republisher.graph.port.spawner
            if spawn is None:
                raise TFError("no event loop runs this graph")
            self.republisher.reserve()
        except RwtError as exc:
            _episodes.log(
                logging.WARNING, "tf_goal_rejected", "TF goal %s rejected: %s", key, exc.message
            )
            self._publish_result(goal_id, REJECTED, exc.message)
            return
        old = self.goals.get(key)
        if old is not None:
            old.canceled = True
        state = self.goals[key] = _Goal(goal_id)
        self._publish_status()

        async def run() -> None:
            try:
                await self._run(state, subscription)
            except Exception:  # a spawned job must not take the server down
                _episodes.log(
                    logging.ERROR, "tf_goal_failed", "TF goal %s failed", key, exc_info=True
                )
            finally:
                self.republisher.release()
                if self.goals.get(key) is state:
                    del self.goals[key]
                self._publish_result(state.goal_id, PREEMPTED, "")
                self._publish_status()

        spawn(run)

    def on_cancel(self, msg: Message) -> None:
        """Cancel one goal by id, or every goal for an empty id (actionlib's rule)."""
        key = str(msg.get("id", ""))
        for goal_key, state in self.goals.items():
            if not key or goal_key == key:
                state.canceled = True

    async def _run(self, state: _Goal, subscription: TFSubscription) -> None:
        clock = self.republisher.graph.clock
        idle_since = clock.monotonic()
        status = {"goal_id": state.goal_id, "status": ACTIVE, "text": ""}
        while not state.canceled:
            now = clock.monotonic()
            if self.republisher.has_subscribers(self.feedback.topic):
                idle_since = now
                transforms = subscription.changed()
                if transforms:
                    self._publish_feedback(status, transforms)
            elif now - idle_since >= ORPHAN_TIMEOUT_S:
                logger.debug("TF goal %s: nobody reads its feedback, ended", state.goal_id["id"])
                return
            await self.republisher.sleep(subscription.request.period_s)

    def _publish_feedback(self, status: Message, transforms: list[Message]) -> None:
        """Publish ``TFSubscriptionActionFeedback``, checking only its small envelope.

        The header (stamped now, D8) and status are converted as any publish is;
        the transforms are already in the internal form (``TFSubscription.changed``)
        and are not checked again, one by one, at every tick.
        """
        msgtype = self.feedback.msgtype
        envelope = {"status": status, "feedback": {"transforms": []}}
        msg = msgtype.from_python(envelope, now=self.republisher.graph.clock.wall())
        msg["feedback"] = {"transforms": transforms}
        self.feedback.publish(msg, validated=True)

    def _publish_status(self) -> None:
        self.status.publish(
            {
                "status_list": [
                    {"goal_id": state.goal_id, "status": ACTIVE, "text": ""}
                    for state in self.goals.values()
                ]
            }
        )

    def _publish_result(self, goal_id: Message, status: int, text: str) -> None:
        self.result.publish({"status": {"goal_id": goal_id, "status": status, "text": text}})
