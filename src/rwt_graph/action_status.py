"""The ``<action>/_action/status`` topic of each action the graph serves (ROS 2).

A ROS 2 action server publishes ``action_msgs/msg/GoalStatusArray`` on
``<action>/_action/status`` at every goal transition, transient local, so a late
subscriber gets the last list (rclcpp ``ServerBase::publish_status``); tools
read it to show what an action is doing (``ros2 action info``, ros-mcp's
``get_action_status``). The graph does the same for the actions its clients and
in-process code serve (docs/agents.md): a goal is listed EXECUTING when its
provider has it, CANCELING once a cancel is asked, then with its terminal status.

Goals here are named by rosbridge ids, so each gets a random UUID for the list
and its acceptance time as its stamp. A ROS 2 server lists a finished goal until
its result expires (15 minutes by default); here the last ``FINISHED_KEPT``
finished goals stay listed, and one list holds at most ``MAX_STATUS_GOALS``
goals, the newest (docs/limits.md).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from itertools import islice
from typing import TYPE_CHECKING

from rwt_protocol.ports import GoalStatus

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId

__all__ = [
    "FINISHED_KEPT",
    "GOAL_STATUS_ARRAY",
    "MAX_STATUS_GOALS",
    "STATUS_SUFFIX",
    "StatusBoard",
    "status_topic",
]

GOAL_STATUS_ARRAY = "action_msgs/msg/GoalStatusArray"
STATUS_SUFFIX = "/_action/status"

FINISHED_KEPT = 16
"""Finished goals an action's status list keeps (the oldest finished goes first)."""

MAX_STATUS_GOALS = 256
"""Goals one ``GoalStatusArray`` lists at most: the newest, so a list costs at most this."""

_TERMINAL = frozenset({GoalStatus.SUCCEEDED, GoalStatus.CANCELED, GoalStatus.ABORTED})


def status_topic(action: str) -> str:
    """The status topic of a resolved action name: ``/fib/_action/status``."""
    return f"{action.rstrip('/')}{STATUS_SUFFIX}"


@dataclass(slots=True)
class _Listed:
    """One goal as the list shows it."""

    uuid: bytes
    sec: int
    nanosec: int
    status: GoalStatus


class StatusBoard:
    """The goals of one action and their status, published on each change.

    Args:
        topic: the status topic (``status_topic``).
        publisher: the participant that publishes it (the action's provider).
        publish: ``publish(client, topic, msg)``: deliver one ``GoalStatusArray``
            (internal form) latched.
        now: seconds since the epoch (the goals' stamps).
    """

    def __init__(
        self,
        topic: str,
        publisher: ClientId,
        publish: Callable[[ClientId, str, dict[str, object]], None],
        now: Callable[[], float],
    ) -> None:
        self.topic = topic
        self.publisher = publisher
        self._publish = publish
        self._now = now
        self._goals: dict[str, _Listed] = {}  # by goal key, in acceptance order
        self._finished: dict[str, None] = {}  # keys of finished goals, oldest first

    def change(self, key: str, status: GoalStatus) -> None:
        """Goal ``key`` is now in ``status`` (a new key is a new goal); publish the list.

        A finished goal keeps its terminal status (a late cancel changes nothing).
        """
        listed = self._goals.get(key)
        if listed is None:
            stamp = self._now()
            sec = int(stamp)
            nanosec = min(int((stamp - sec) * 1e9), 999_999_999)
            listed = self._goals[key] = _Listed(os.urandom(16), sec, nanosec, status)
        elif listed.status in _TERMINAL or listed.status == status:
            return
        listed.status = status
        if status in _TERMINAL:
            self._finished[key] = None
            while len(self._finished) > FINISHED_KEPT:
                oldest = next(iter(self._finished))
                del self._finished[oldest]
                del self._goals[oldest]
        self._publish(self.publisher, self.topic, self.message())

    def message(self) -> dict[str, object]:
        """The ``GoalStatusArray`` now (internal form): the newest ``MAX_STATUS_GOALS`` goals."""
        newest = list(islice(reversed(self._goals.values()), MAX_STATUS_GOALS))
        newest.reverse()
        return {
            "status_list": [
                {
                    "goal_info": {
                        "goal_id": {"uuid": goal.uuid},
                        "stamp": {"sec": goal.sec, "nanosec": goal.nanosec},
                    },
                    "status": int(goal.status),
                }
                for goal in newest
            ]
        }
