"""The ROS 2 link: ``rwt serve --ros2``, a graph mirrored to and from ROS 2 through rclpy.

See docs/ros2.md. rclpy is imported only when a link opens, so this package
imports without ROS. An interface package rclpy lacks (``tf2_msgs`` with only the pip
extra) is built on first use (``ondemand``, ``interfaces``; the command
``python -m rwt_ros2.build``).
"""

from .link import PARTICIPANT_PREFIX, Ros2Link, Ros2Options, open_ros2_link
from .runtime import ROS2_INSTALL, Ros2Unavailable

__all__ = [
    "PARTICIPANT_PREFIX",
    "ROS2_INSTALL",
    "Ros2Link",
    "Ros2Options",
    "Ros2Unavailable",
    "open_ros2_link",
]
