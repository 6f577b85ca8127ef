"""Fixtures of the ROS 2 link's tests: a private ROS 2 domain and `rwt serve --ros2` per module."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from .support import ros_environment, serve_ros2

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    from tests.integration.client_harness import ServerProcess


@pytest.fixture(scope="module")
def ros_env(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Path]:
    """The module's ROS 2 environment (domain, loopback discovery); yields a work directory."""
    tmp = tmp_path_factory.mktemp("ros2")
    with ros_environment(request.module.__name__, tmp):
        yield tmp


@pytest.fixture(scope="module")
def server(ros_env: Path) -> Iterator[ServerProcess]:
    """One `rwt serve --ros2` for the module."""
    process = serve_ros2(ros_env)
    try:
        yield process
    finally:
        process.stop()
