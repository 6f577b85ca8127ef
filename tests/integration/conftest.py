"""Fixtures for the real-client integration tests: a fresh `rwt serve` per test."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from .client_harness import SERVE_FIXTURE, TEST_INTERFACES, ServerProcess, node_missing_reason

_NODE_MISSING = node_missing_reason()


def pytest_runtest_setup(item: pytest.Item) -> None:
    if item.get_closest_marker("node") is not None and _NODE_MISSING is not None:
        pytest.skip(f"roslib-in-Node tests skipped: {_NODE_MISSING}")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator:
    """On a failure, attach the server's stderr to the report."""
    report = yield
    server = getattr(item, "_rwt_server", None)
    if server is not None and report.failed:
        report.sections.append(("rwt serve stderr", server.stderr_text() or "<empty>"))
    return report


@pytest.fixture
def rwt_server(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ServerProcess]:
    """`rwt serve --port 0` in a subprocess; yields it (`.url`, `.port`)."""
    server = ServerProcess(tmp_path)
    request.node._rwt_server = server
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def fixture_server(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ServerProcess]:
    """serve_fixture.py: in-process services, a Fibonacci action and an in-process caller."""
    cmd = [sys.executable, str(SERVE_FIXTURE), "--interfaces", str(TEST_INTERFACES)]
    server = ServerProcess(tmp_path, cmd=cmd, control=True)
    request.node._rwt_server = server
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def interfaces_server(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ServerProcess]:
    """`rwt serve --interfaces tests/integration/data` (the custom rwt_test_interfaces)."""
    server = ServerProcess(tmp_path, ("--interfaces", str(TEST_INTERFACES)))
    request.node._rwt_server = server
    try:
        yield server
    finally:
        server.stop()
