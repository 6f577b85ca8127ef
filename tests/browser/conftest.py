"""Fixtures of the browser tests: one Chromium a test process, one `rwt serve --video` a module."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.integration.client_harness import ServerProcess, _LineReader

from .cdp import Browser, chromium_path


@pytest.fixture(scope="session")
def browser() -> Iterator[Browser]:
    """One Chromium a test process, for every module that asks (0.6 s of CPU a start).

    Each test opens its pages and closes them; pages of different servers never share
    an origin (each server has a port of its own).
    """
    executable = chromium_path()
    if executable is None:
        pytest.skip("chromium is not installed (apt-get install chromium; .ci/run does it as root)")
    browser = Browser(executable)
    try:
        yield browser
    finally:
        browser.close()


@pytest.fixture(scope="module")
def video_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, str]]:
    """`rwt serve --video`: (the WebSocket URL, the video server's URL)."""
    workdir: Path = tmp_path_factory.mktemp("serve")
    server = ServerProcess(workdir, ("--video", "--video-port", "0"))
    try:
        line = server.next_stdout_line()
        assert line is not None and line.startswith("video on http://"), line
        yield server.url, line.removeprefix("video on ")
    finally:
        server.stop()


class RobotProcess:
    """robot.py (roslibpy) in a subprocess; ``next_command`` reads what it received."""

    def __init__(self, ws_url: str) -> None:
        host, port = ws_url.removeprefix("ws://").rsplit(":", 1)
        self.proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).with_name("robot.py")), host, port],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )
        self.stdout = _LineReader(self.proc.stdout, "robot-stdout")
        line = self.stdout.get(time.monotonic() + 20)
        if line != "ready":
            self.close()
            raise RuntimeError(f"robot.py did not start: {line!r}")

    def next_command(self, timeout_s: float = 10.0) -> dict:
        """The next message the page published on /console_test/command."""
        line = self.stdout.get(time.monotonic() + timeout_s)
        assert line is not None, "robot.py ended"
        return json.loads(line)

    def close(self) -> None:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.close()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(10)
        self.proc.stdout.close()


@pytest.fixture(scope="module")
def robot(video_server: tuple[str, str]) -> Iterator[RobotProcess]:
    robot = RobotProcess(video_server[0])
    try:
        yield robot
    finally:
        robot.close()
