"""``rwt serve --ros2``: the command line's side of the ROS 2 link (docs/ros2.md).

rclpy loads only when ``--ros2`` is given, so a plain ``rwt serve`` neither
needs nor imports it.
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING

from rwt_protocol.errors import ConfigError
from rwt_transports.process.gcfreeze import freeze_startup_objects

if TYPE_CHECKING:
    from collections.abc import AsyncIterator
    from pathlib import Path

    from rwt_graph.graph import Graph
    from rwt_ros2 import Ros2Options

__all__ = ["linked_ros2", "ros2_interface_dirs", "ros2_options"]


def ros2_options(node_name: str, namespace: str) -> Ros2Options:
    """The link's options from the command line, rclpy checked importable.

    Raises:
        ConfigError: rclpy cannot be imported; the text says what to install or source.
    """
    from rwt_ros2 import Ros2Options, Ros2Unavailable  # noqa: PLC0415
    from rwt_ros2.runtime import load_rclpy  # noqa: PLC0415

    try:
        load_rclpy()
    except Ros2Unavailable as exc:
        raise ConfigError(str(exc)) from None
    return Ros2Options(node_name=node_name, namespace=namespace)


def ros2_interface_dirs() -> list[Path]:
    """The ROS 2 install's interface folders (``rwt_ros2.runtime.ament_interface_dirs``)."""
    from rwt_ros2.runtime import ament_interface_dirs  # noqa: PLC0415

    return ament_interface_dirs()


@contextlib.asynccontextmanager
async def linked_ros2(graph: Graph, options: Ros2Options | None) -> AsyncIterator[None]:
    """Link ``graph`` to ROS 2 while the block runs (nothing when ``options`` is None).

    Raises:
        ConfigError: rclpy cannot start its node (a bad name, the middleware fails): one line.
    """
    if options is None:
        yield
        return
    from rwt_ros2 import open_ros2_link  # noqa: PLC0415

    try:
        async with open_ros2_link(graph, options):
            # rclpy, its node and the ROS 2 type store came after the start-up freeze
            freeze_startup_objects()
            yield
    except (RuntimeError, ValueError) as exc:  # rclpy's RCLError is a RuntimeError
        raise ConfigError(f"ros2: {exc}") from None
