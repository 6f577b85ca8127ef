"""Loading rclpy and the generated Python classes of ROS 2 types, with errors that say what to do.

rclpy comes from a ROS 2 install (``source /opt/ros/<distro>/setup.bash``) or,
on a machine without ROS, from PyPI's ROS 2 Kilted wheels (``rwt-rosbridge[ros2]``). It
needs the generated Python package of every type it carries; a missing one is
named with the package to install (docs/ros2.md).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import os
import re
import sys
from pathlib import Path
from typing import Any

from rwt_protocol.distribution import install_hint
from rwt_protocol.errors import GraphError, RwtError

from .interfaces import BUILDS, COMMAND

__all__ = [
    "KILTED_WHEELS",
    "ROS2_INSTALL",
    "Ros2Unavailable",
    "ament_interface_dirs",
    "interface_class",
    "load_rclpy",
    "package_hint",
    "ros_distro",
]

ROS2_INSTALL = (
    f"{install_hint('ros2')} (ROS 2 Kilted from PyPI), "
    "or source your ROS 2 install first: source /opt/ros/<distro>/setup.bash"
)
"""What to do when rclpy cannot be imported."""


class Ros2Unavailable(RwtError, RuntimeError):
    """rclpy cannot be imported; the text says what to install or source (also a RuntimeError)."""


def load_rclpy() -> Any:
    """Import rclpy (the wheels' bootstrapper has set the library path by then).

    Returns:
        The ``rclpy`` module.

    Raises:
        Ros2Unavailable: rclpy or its libraries are missing.
    """
    try:
        return importlib.import_module("rclpy")
    except ImportError as exc:  # the module, or one of its shared libraries
        raise Ros2Unavailable(f"--ros2 needs rclpy ({exc}): {ROS2_INSTALL}") from None


def ros_distro() -> str | None:
    """The ROS 2 distribution rclpy comes from, or None when nothing says.

    In this order: ``ROS_DISTRO`` (set by a sourced install's ``setup.bash``), the
    name of PyPI's ``ros-<distro>-rclpy`` wheel, the ``/opt/ros/<distro>`` directory
    rclpy lies in. rosapi's ``get_ros_version`` reports it (docs/ros2.md).
    """
    named = os.environ.get("ROS_DISTRO", "").strip()
    if named:
        return named
    for dist in importlib.metadata.distributions():
        wheel = re.fullmatch(r"ros-([a-z]+)-rclpy", dist.name or "")
        if wheel:
            return wheel[1]
    spec = importlib.util.find_spec("rclpy")
    installed = re.search(r"/opt/ros/([a-z]+)/", (spec.origin or "") if spec else "")
    return installed[1] if installed else None


KILTED_WHEELS = frozenset(
    {
        "action_msgs",
        "actionlib_msgs",
        "builtin_interfaces",
        "diagnostic_msgs",
        "geometry_msgs",
        "lifecycle_msgs",
        "nav_msgs",
        "rcl_interfaces",
        "rosgraph_msgs",
        "sensor_msgs",
        "service_msgs",
        "shape_msgs",
        "std_msgs",
        "std_srvs",
        "stereo_msgs",
        "test_msgs",
        "trajectory_msgs",
        "type_description_interfaces",
        "unique_identifier_msgs",
        "visualization_msgs",
    }
)
"""The interface packages PyPI has a ``ros-kilted-<package>`` wheel of (as of 2025-11; the
test extra installs some, docs/ros2.md). Others (``tf2_msgs``, ``example_interfaces``)
come from a ROS install (``apt``) or a build of the package (rwt builds ``tf2_msgs``
itself: ``rwt_ros2.build``)."""


def package_hint(package: str) -> str:
    """How to get the generated Python package of the ROS 2 package ``package``.

    A PyPI wheel is named only where one exists (``KILTED_WHEELS``); rwt's own build
    command where rwt builds the package (``interfaces.BUILDS``).
    """
    debian = f"apt install ros-<distro>-{package.replace('_', '-')}"
    if package in BUILDS:
        return f"{debian} (PyPI has no wheel of it), or build it for rclpy: {COMMAND} {package}"
    if package not in KILTED_WHEELS:
        return f"{debian} (PyPI has no wheel of it), or build it for rclpy"
    return f"pip install ros-kilted-{package.replace('_', '-')}, or {debian}"


def interface_class(type_name: str) -> Any:
    """The generated rclpy class of ``pkg/msg/Name``, ``pkg/srv/Name`` or ``pkg/action/Name``.

    Raises:
        GraphError: the package or the type is not installed for rclpy; the text
            names the package to install.
    """
    package, _, rest = type_name.partition("/")
    kind, _, name = rest.partition("/")
    if not package or kind not in {"msg", "srv", "action"} or not name:
        raise GraphError(f"{type_name} is not a ROS 2 type name (pkg/msg/Name)")
    try:
        module = importlib.import_module(f"{package}.{kind}")
    except ImportError:
        raise GraphError(
            f"ROS 2 has no Python package for {type_name}: {package_hint(package)}"
        ) from None
    cls = getattr(module, name, None)
    if cls is None:
        raise GraphError(
            f"ROS 2 package {package} has no {kind} {name}: update it ({package_hint(package)})"
        )
    return cls


def ament_interface_dirs() -> list[Path]:
    """The ``share`` folders of the ROS 2 install, for the graph's type registry.

    Each holds ``<pkg>/msg|srv|action/*`` as ``--interfaces`` folders do, so the
    graph knows every type the robot has (``test_msgs``, the robot's own
    packages). The prefixes are ``AMENT_PREFIX_PATH``'s (a sourced install), or
    this Python's prefix, where PyPI's ROS 2 wheels put theirs.
    """
    prefixes = os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
    roots = [Path(p) for p in prefixes if p] or [Path(sys.prefix)]
    return [root / "share" for root in roots if (root / "share").is_dir()]
