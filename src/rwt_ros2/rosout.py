"""rwt's own log on ROS 2's ``/rosout``, as any ROS 2 node's.

While the link runs, each record of the ``rwt`` loggers at ``ROSOUT_LEVEL`` or
above also goes to the link node's rclpy logger, which rcl publishes on
``/rosout`` (``rcl_interfaces/msg/Log``, named after the node), so ``ros2
topic echo /rosout``, rqt_console and rosbridge clients subscribed to
``/rosout`` see it. Lines a peer can cause are already one per episode
(``rwt_graph.ratelog``), so this adds no unbounded traffic.
"""

from __future__ import annotations

import logging
from typing import Any

__all__ = ["ROSOUT_LEVEL", "RosoutHandler"]

ROSOUT_LEVEL = logging.INFO
"""The lowest level of rwt's records that go to /rosout."""


class RosoutHandler(logging.Handler):
    """Forwards log records to an rclpy logger (see the module text).

    Args:
        ros_logger: the link node's ``rclpy`` logger (``node.get_logger()``);
            rclpy's logging is thread safe, so any thread may log.
    """

    def __init__(self, ros_logger: Any) -> None:
        super().__init__(ROSOUT_LEVEL)
        self._logger = ros_logger

    def emit(self, record: logging.LogRecord) -> None:
        """Log ``record`` at its severity (never raises: logging must not fail rwt)."""
        try:
            text = f"{record.name}: {record.getMessage()}"
            if record.levelno >= logging.CRITICAL:
                self._logger.fatal(text)
            elif record.levelno >= logging.ERROR:
                self._logger.error(text)
            elif record.levelno >= logging.WARNING:
                self._logger.warning(text)
            else:
                self._logger.info(text)
        except Exception:  # the context went down meanwhile
            self.handleError(record)

    def handleError(self, record: logging.LogRecord) -> None:
        """Drop the record quietly: the console still has it."""
