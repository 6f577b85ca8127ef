"""Ctrl-C stops every example that serves forever quietly: no KeyboardInterrupt traceback."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from .client_harness import AS_A_SHELL_STARTS_IT, REPO

ENV = {**os.environ, "PYTHONPATH": str(REPO / "src"), "PYTHONUNBUFFERED": "1"}
TIMEOUT_S = 60  # a bound on a hung example, not a speed requirement

#: Each example that runs until interrupted, with the arguments that pick a free port.
SERVING = {
    "embedded_server.py": ["--port", "0"],
    "moving_robot.py": ["0"],
    "robot.py": ["0"],
    "tf_robot.py": ["0"],
}


def test_every_example_is_covered() -> None:
    assert set(SERVING) == {path.name for path in (REPO / "examples").glob("*.py")}


def _signals() -> str:
    """This process's ignored and blocked signals (a child inherits both), as /proc has them."""
    try:
        status = Path(f"/proc/self/task/{threading.get_native_id()}/status").read_text()
    except OSError:
        return "no /proc"
    return " ".join(line for line in status.splitlines() if line.startswith(("SigIgn", "SigBlk")))


@pytest.mark.parametrize("example", sorted(SERVING))
def test_ctrl_c_stops_the_example_quietly(example: str) -> None:
    process = subprocess.Popen(
        [
            *AS_A_SHELL_STARTS_IT,
            sys.executable,
            str(REPO / "examples" / example),
            *SERVING[example],
        ],
        env=ENV,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        ready = process.stdout.readline()  # blocks until it serves (or ends)
        process.send_signal(signal.SIGINT)
        try:
            _, stderr = process.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            _, stderr = process.communicate()
            pytest.fail(f"{example} still ran {TIMEOUT_S} s after SIGINT ({_signals()}): {stderr}")
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert ready.startswith("listening on ws://"), stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    assert process.returncode in (0, 130), stderr
