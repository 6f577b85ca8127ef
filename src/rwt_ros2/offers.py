"""The rclpy services and action servers the link offers, and how they leave.

A server whose graph provider goes may still hold calls from ROS 2: the graph
fails them (D15, docs/decisions.md) and each callback returns a default
response, which rclpy sends *after* the callback returns, from the same
executor step (a goal's result: from a task that step queues). Destroying the
rclpy entity from the event loop in between makes that send raise
``InvalidHandle`` instead of answering, and the caller waits for ever. So an
offer leaves in two steps: ``retire`` (event loop) marks it, and the executor's
own thread destroys it in a task queued once no call is inside it and run
after the tasks that send the answers.
"""

from __future__ import annotations

import logging
from typing import Any

__all__ = ["Offer"]

logger = logging.getLogger("rwt.ros2")

HOPS = 2
"""Executor tasks between the last call leaving and the destruction: the first
runs after the step that sent a service's response, the second after the task
that step queued to send a goal's result (rclpy runs tasks in the order queued)."""


class Offer:
    """One rclpy service or action server offering a graph entity to ROS 2.

    Args:
        type_name: the graph entity's type (``std_srvs/srv/SetBool``).
        executor: the node's rclpy executor (``RosNode.executor``).
        destroy: destroys ``handle`` (``node.destroy_service``, ``ActionServer.destroy``).

    Attributes:
        handle: the rclpy entity, set once made; None once destroyed.
        calls: calls or goals inside its callback (the executor's thread only).
        retired: the graph entity went; destroyed once ``calls`` is 0.
    """

    def __init__(self, type_name: str, executor: Any, destroy: Any) -> None:
        self.type_name = type_name
        self.handle: Any = None
        self.calls = 0
        self.retired = False
        self._executor = executor
        self._destroy = destroy

    def enter(self) -> None:
        """A call or goal entered the callback (the executor's thread)."""
        self.calls += 1

    def leave(self) -> None:
        """It left; the last one out of a retired offer queues its destruction."""
        self.calls -= 1
        if self.retired and self.calls == 0:
            self._executor.create_task(self._end, HOPS)

    def retire(self) -> None:
        """The graph entity went: destroy once no call is inside (the event loop)."""
        self.retired = True
        self._executor.create_task(self._end, HOPS)

    def destroy(self) -> None:
        """Destroy now (the link stops: no executor task runs after it)."""
        handle, self.handle = self.handle, None
        if handle is not None:
            try:
                self._destroy(handle)
            except Exception:  # the context is going: nothing left to destroy
                logger.debug("ros2 link: destroying %r failed", handle, exc_info=True)

    def _end(self, hops: int) -> None:  # an executor task
        if self.calls or self.handle is None:
            return  # a call came in meanwhile: the last one out queues it again
        if hops > 1:
            self._executor.create_task(self._end, hops - 1)
        else:
            self.destroy()
