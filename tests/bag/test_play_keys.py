"""``rwt play``'s keyboard controls on a terminal (docs/record-replay.md, Replaying).

``rwt play --start-paused`` runs with a pseudo-terminal as its standard input; a
roslibpy client subscribes and types the keys into that terminal as a user would:
the right arrow publishes exactly the next message, up and down change the rate
(``/rwt/player/get_status`` says so), space resumes. The terminal's modes are
restored when ``rwt play`` ends. Off a terminal (the other tests) no key is read.
"""

from __future__ import annotations

import json
import os
import pty
import subprocess
import sys
import termios
import textwrap
from pathlib import Path

import anyio
import pytest

from tests.integration.client_harness import REPO
from tests.support.cli import RWT

from .test_play_options import COUNT, write_chatter

pytestmark = pytest.mark.anyio

TYPIST = """
import json, os, time
import roslibpy
ros = roslibpy.Ros("127.0.0.1", {port})
ros.run(timeout=20)
got = []
roslibpy.Topic(ros, "/chatter", "std_msgs/msg/String").subscribe(lambda m: got.append(m["data"]))
status = roslibpy.Service(ros, "/rwt/player/get_status", "rwt_msgs/srv/GetPlayerStatus")

def wait_for(predicate, within=20.0):
    end = time.monotonic() + within
    while not predicate() and time.monotonic() < end:
        time.sleep(0.05)

def rate():
    return status.call(roslibpy.ServiceRequest({{}}), timeout=20)["rate"]

def press(key):
    os.write({fd}, key)

time.sleep(0.5)  # the subscription is in before the first key
out = {{}}
press(b"\\x1b[C")  # right arrow: one message
wait_for(lambda: len(got) >= 1)
time.sleep(0.3)  # and no more
out["one"] = list(got)
press(b"\\x1b[C")
wait_for(lambda: len(got) >= 2)
time.sleep(0.3)
out["two"] = list(got)
press(b"\\x1b[A")  # up: 10 % faster
wait_for(lambda: rate() != 1.0)
out["up"] = rate()
press(b"\\x1b[B")  # down: 10 % slower
wait_for(lambda: abs(rate() - 1.0) < 1e-9)
out["down"] = rate()
press(b" ")  # space: play on
wait_for(lambda: len(got) >= {count})
out["all"] = len(got)
print(json.dumps(out))
ros.terminate()
"""


async def test_keys_step_change_the_rate_and_resume(tmp_path: Path) -> None:
    bag = write_chatter(tmp_path / "bag")
    master, slave = pty.openpty()
    before = termios.tcgetattr(slave)
    command = [*RWT, "play", str(bag), "--port", "0"]
    env = {"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"}
    rwt_play = None
    try:
        rwt_play = subprocess.Popen(  # noqa: ASYNC220 - its output is read in the test's thread
            [*command, "--start-paused"],
            stdin=slave,
            stdout=subprocess.PIPE,
            text=True,
            cwd=tmp_path,
            env=env,
        )
        with rwt_play:
            assert rwt_play.stdout is not None
            lines = [rwt_play.stdout.readline() for _ in range(2)]  # in either order
            (listening,) = [ln for ln in lines if ln.startswith("listening on ws://127.0.0.1:")]
            assert any(ln.startswith("keys: space pause/resume") for ln in lines), lines
            port = int(listening.rsplit(":", 1)[1])
            script = TYPIST.format(port=port, fd=master, count=COUNT)
            out = await run_python_with_fd(script, master)
            assert rwt_play.wait(timeout=30) == 0
        after = termios.tcgetattr(slave)
    finally:
        if rwt_play is not None and rwt_play.poll() is None:
            rwt_play.kill()  # a failed step: no hang on the pipe
        os.close(master)
        os.close(slave)
    got = json.loads(out.strip().splitlines()[-1])
    assert got["one"] == ["m0"]
    assert got["two"] == ["m0", "m1"]
    assert got["up"] == pytest.approx(1.1)
    assert got["down"] == pytest.approx(1.0)
    assert got["all"] == COUNT
    assert after[3] & termios.ECHO  # cbreak mode is undone: the terminal echoes again
    assert after == before


async def run_python_with_fd(code: str, fd: int) -> str:
    """Run ``code`` (as ``run_python``) in a child that keeps ``fd``, the terminal it types into."""
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    with anyio.fail_after(60):
        done = await anyio.run_process(
            [sys.executable, "-c", textwrap.dedent(code)],
            env=env,
            cwd=REPO,
            check=False,
            stdin=subprocess.DEVNULL,
            pass_fds=(fd,),
        )
    assert done.returncode == 0, done.stderr.decode("utf-8", "replace")
    return done.stdout.decode("utf-8")
