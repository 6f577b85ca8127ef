"""Start this test process's warm ``rwt`` (zygote.py) and say where it listens.

``start()`` runs once per test process that runs tests (each xdist worker, or the one
process of ``-n 0``): it sets ``RWT_TEST_WARM`` in ``os.environ`` before any test
builds a command's environment, and starts the zygote beside the collection. The
zygote ends when this process does (its stdin is this process's pipe).
``RWT_TEST_WARM=0`` in the environment keeps every run cold.
"""

from __future__ import annotations

import atexit
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
ZYGOTE = HERE / "zygote.py"
WARM_RWT = HERE / "warm_rwt.py"
#: ``python`` for the tests' Python clients: ``[*PYTHON, "-c", CODE]`` or ``[*PYTHON, SCRIPT]``,
#: forked by this worker's zygote with roslibpy's libraries loaded, or cold.
PYTHON = [sys.executable, "-S", str(WARM_RWT), "--python"]
_started: list[subprocess.Popen[bytes]] = []
_ros2: list[str] = []


def rwt_env() -> dict[str, str]:
    """The environment of an ``rwt`` the tests start: this checkout's src first, unbuffered."""
    path = os.pathsep.join(filter(None, [str(REPO / "src"), os.environ.get("PYTHONPATH")]))
    return {**os.environ, "PYTHONPATH": path, "PYTHONUNBUFFERED": "1"}


def start() -> None:
    """Start the zygote and set ``RWT_TEST_WARM`` to its socket (once; not if set to 0)."""
    if _started or os.environ.get("RWT_TEST_WARM") == "0":
        return
    os.environ["RWT_TEST_WARM"] = _spawn()


def ros2_socket() -> str | None:
    """The socket of this test process's warm rclpy (a second zygote, started on first use).

    The tests' rclpy nodes (tests/ros2/peer.py) are forked by it with rclpy and their
    messages loaded (0.35 s of CPU a start). It is a process of its own because
    importing rclpy starts threads, after which the ``rwt`` zygote could not fork
    safely. None where the warm ``rwt`` is off (``RWT_TEST_WARM=0``, or never started).
    """
    if not _started or os.environ.get("RWT_TEST_WARM") in (None, "0"):
        return None
    if _ros2:
        return _ros2[0]
    _ros2.append(_spawn("ros2"))
    return _ros2[0]


def _spawn(*kind: str) -> str:
    """Start a zygote (``kind``: its preload, default ``rwt``'s); its socket's path."""
    folder = tempfile.mkdtemp(prefix="rwt-warm-")
    path = os.path.join(folder, "zygote.sock")
    env = {**rwt_env(), "RWT_TEST_WARM": path}
    given = os.path.join(folder, "env.json")
    with open(given, "w", encoding="utf-8") as file:
        json.dump(env, file)
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    with open(os.path.join(folder, "zygote.log"), "wb") as log:
        _started.append(
            subprocess.Popen(
                [sys.executable, str(ZYGOTE), path, given, *kind],
                env=env,
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                stderr=log,
                cwd=folder,
                start_new_session=True,
            )
        )
    return path
