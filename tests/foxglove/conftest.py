"""Shared fixtures of the Foxglove tests."""

from __future__ import annotations

import pytest

from rwt_graph.types import Dialect, TypeRegistry


@pytest.fixture(scope="session")
def ros2_types() -> TypeRegistry:
    """ROS 2 message types for the tests' graphs (each test still has its own graph).

    A registry builds its rosbags typestore at its first CDR message (about 0.6 s)
    and only ever adds what it loads on demand: the types are the same for every
    test, so they are built once.
    """
    return TypeRegistry(Dialect.ROS2)
