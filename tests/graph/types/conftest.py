"""Shared fixtures of the type registry tests."""

from __future__ import annotations

import pytest
from types_support import DATA

from rwt_graph.types import Dialect, TypeRegistry


@pytest.fixture(scope="session")
def ros2() -> TypeRegistry:
    return TypeRegistry(Dialect.ROS2, [DATA])


@pytest.fixture(scope="session")
def ros1() -> TypeRegistry:
    return TypeRegistry(Dialect.ROS1, [DATA])
