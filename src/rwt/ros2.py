"""The ROS 2 link: the graph mirrored to a real ROS 2 graph through rclpy (docs/ros2.md).

``open_ros2_link`` raises ``Ros2Unavailable`` where rclpy cannot be imported.

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_ros2 import Ros2Link, Ros2Options, Ros2Unavailable, open_ros2_link
    from rwt_ros2.runtime import ament_interface_dirs

__all__ = [
    "Ros2Link",
    "Ros2Options",
    "Ros2Unavailable",
    "ament_interface_dirs",
    "open_ros2_link",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
