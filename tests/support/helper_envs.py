"""The tools' own environments and folders, started by the xdist controller, once.

On a new machine (an empty ``~/.cache``) each xdist worker would find at collection
that ros-mcp's environment, the code generator's, the Inspector's npm folder and the
MCP Apps host are missing, and make them at once. Each is made under its lock now
(``toolenv.locked``), so a worker that asks waits for the one process making it. The
controller starts them here, in threads, before its workers start, for the runs that
collect a module that needs one: their installs (mostly downloads) then overlap the
workers' start instead of holding every worker's collection in turn. The ``tf2_msgs``
build for rclpy (``python -m rwt_ros2.build``, its own lock) starts the same way.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Callable, Iterable
from pathlib import Path

from .apphost import app_host
from .inspector import inspector_bin
from .openapi_client import openapi_generator
from .ros_mcp import ros_mcp_python

__all__ = ["MAKERS", "start"]


def _tf2_msgs() -> object:
    """Build tf2_msgs for rclpy as docs/ros2.md says (a no-op once cached)."""
    command = [sys.executable, "-m", "rwt_ros2.build", "tf2_msgs"]
    return subprocess.run(command, capture_output=True, check=False, timeout=900)


MAKERS: dict[str, tuple[Callable[[], object], tuple[str, ...]]] = {
    "ros-mcp": (
        ros_mcp_python,
        ("agents/test_ros_mcp.py", "benchmarks/test_mcp_latency.py", "docs/test_code_blocks.py"),
    ),
    "openapi-python-client": (openapi_generator, ("http/test_codegen.py",)),
    "mcp-inspector": (inspector_bin, ("agents/test_mcp_inspector.py",)),
    "mcp-app-host": (app_host, ("browser/test_mcp_app.py",)),
    "tf2_msgs": (_tf2_msgs, ("ros2/test_tf.py",)),
}
"""Each tool: what makes it, and the test files (under tests/) that use it."""


def _wanted(tests_root: Path, args: Iterable[str], users: tuple[str, ...]) -> bool:
    """Whether a run of ``args`` collects one of ``users``."""
    chosen = [os.path.abspath(arg.partition("::")[0]) for arg in args]
    for user in users:
        path = str(tests_root / user)
        if any(path == c or path.startswith(c + os.sep) for c in chosen):
            return True
    return False


def start(tests_root: Path, args: Iterable[str]) -> list[threading.Thread]:
    """Start making, in daemon threads, each tool a run of ``args`` needs; the threads.

    A thread that is still making when the run ends leaves no ready mark, so the next
    run makes that folder again.
    """
    args = list(args) or [str(tests_root)]
    threads = []
    for name, (make, users) in MAKERS.items():
        if _wanted(tests_root, args, users):
            thread = threading.Thread(target=make, name=f"make {name}", daemon=True)
            thread.start()
            threads.append(thread)
    return threads
