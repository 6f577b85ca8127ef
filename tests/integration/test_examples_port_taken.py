"""An example whose port is taken says so in one line and exits 1: no traceback."""

from __future__ import annotations

import subprocess
import sys

import pytest

from .client_harness import REPO
from .test_examples_interrupt import ENV, SERVING, TIMEOUT_S


@pytest.mark.parametrize("example", sorted(SERVING))
def test_a_taken_port_is_one_line_and_exit_code_1(example: str, taken_tcp_port: int) -> None:
    args = [str(taken_tcp_port) if arg == "0" else arg for arg in SERVING[example]]
    done = subprocess.run(
        [sys.executable, str(REPO / "examples" / example), *args],
        env=ENV,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,  # a bound on a hung example, not a speed requirement
        check=False,
    )
    line = f"cannot listen for WebSocket on 127.0.0.1:{taken_tcp_port}: address already in use"
    assert (done.returncode, done.stdout, done.stderr) == (1, "", line + "\n")
