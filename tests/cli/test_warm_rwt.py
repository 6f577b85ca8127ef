"""The tests' warm ``rwt`` (tests/support/zygote.py) behaves as ``python -m rwt`` does.

Most tests run ``rwt`` through it; these compare what a user sees of both (output,
exit code, the end on SIGINT and SIGTERM) and check that a run really is forked.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.integration.client_harness import AS_A_SHELL_STARTS_IT
from tests.support.cli import ENV, RWT, RWT_COLD
from tests.support.warm import PYTHON

TIMEOUT_S = 60  # a hang guard


def _run(command: list[str], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*command, *args], env=ENV, capture_output=True, text=True, timeout=TIMEOUT_S, check=False
    )


@pytest.mark.parametrize(
    "args", [("--version",), ("bag", "info", "/nonexistent.mcap"), ("serve", "--port", "x")]
)
def test_warm_and_cold_runs_print_and_exit_alike(args: tuple[str, ...]) -> None:
    warm, cold = _run(RWT, *args), _run(RWT_COLD, *args)
    seen = warm.returncode, warm.stdout, warm.stderr
    assert seen == (cold.returncode, cold.stdout, cold.stderr)


@pytest.mark.parametrize("number", [signal.SIGINT, signal.SIGTERM])
def test_a_warm_server_ends_on_a_signal_as_a_cold_one(number: int) -> None:
    ends = []
    for command in (RWT, RWT_COLD):
        process = subprocess.Popen(
            [*AS_A_SHELL_STARTS_IT, *command, "serve", "--host", "127.0.0.1", "--port", "0"],
            env=ENV,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert process.stdout is not None
        assert process.stdout.readline().startswith("listening on ws://")
        process.send_signal(number)
        _, err = process.communicate(timeout=TIMEOUT_S)
        ends.append((process.returncode, "Traceback" in err))
    assert ends[0] == ends[1]


def test_a_run_is_forked_by_the_workers_zygote(tmp_path: Path) -> None:
    path = os.environ.get("RWT_TEST_WARM")
    if not path or path == "0":
        pytest.skip("RWT_TEST_WARM=0: every run is cold")
    request = {
        "argv": ["--version"],
        "cwd": str(tmp_path),
        "env": ENV,
        "nofile": [1024, 1024],
        "ignored": [],
    }
    out = tmp_path / "out"
    with open(out, "wb") as stdout, socket.socket(socket.AF_UNIX) as conn:
        for _ in range(200):  # the zygote may still be importing (a hang guard: 20 s)
            if os.path.exists(path):
                break
            time.sleep(0.1)
        conn.connect(path)
        fds = [os.open(os.devnull, os.O_RDONLY), stdout.fileno(), stdout.fileno()]
        socket.send_fds(conn, [json.dumps(request).encode() + b"\n"], fds)
        os.close(fds[0])
        lines = conn.makefile("rb").read().decode().splitlines()
    assert lines[0].startswith("pid ")
    assert lines[1] == "exit 0"
    assert out.read_text().startswith("rwt ")


CLIENT = """
import sys
import roslibpy
print(sys.argv[1:], __name__, sys.path[0] == "", roslibpy.__name__)
sys.exit(int(sys.argv[1]))
"""


@pytest.mark.parametrize("code", ["0", "3"])
def test_a_warm_python_client_runs_as_a_cold_one(code: str) -> None:
    warm, cold = _run(PYTHON, "-c", CLIENT, code), _run([sys.executable], "-c", CLIENT, code)
    seen = warm.returncode, warm.stdout, warm.stderr
    assert seen == (cold.returncode, cold.stdout, cold.stderr)
    assert warm.stdout == f"['{code}'] __main__ True roslibpy\n"
