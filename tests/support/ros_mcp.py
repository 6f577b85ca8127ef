"""An environment of its own for ros-mcp-server 3.1.2, which holds mcp below 2 (D52).

rwt's MCP server is on the SDK's 2.x line; ros-mcp 3.1.2 (through FastMCP 2)
needs 1.x, so the two cannot share an environment, and ros-mcp runs from one of
its own, as a user installs it (``pipx install ros-mcp==3.1.2``). ``RWT_ROS_MCP_PYTHON``
names a Python that has it; else one is made once under ``~/.cache/rwt-tests``
with pip (about 20 s), and reused after. Without either the caller skips.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys
from pathlib import Path

from . import toolenv

__all__ = ["ROS_MCP_PIN", "ros_mcp_python"]

ROS_MCP_PIN = "ros-mcp==3.1.2"
"""The release tests/agents/test_ros_mcp.py checks tool by tool (31 tools)."""
_HOME = toolenv.HOME / ROS_MCP_PIN.replace("==", "-")


def _has_ros_mcp(python: Path) -> bool:
    probe = [str(python), "-c", "import ros_mcp.main"]
    return subprocess.run(probe, capture_output=True, check=False, timeout=120).returncode == 0


@functools.cache
def ros_mcp_python() -> tuple[Path | None, str]:
    """A Python that runs ros-mcp 3.1.2: ``(path, "")``, or ``(None, why not)``."""
    named = os.environ.get("RWT_ROS_MCP_PYTHON")
    if named:
        path = Path(named)
        return (path, "") if _has_ros_mcp(path) else (None, f"{named} cannot import ros_mcp")
    python = toolenv.bin_dir(_HOME) / ("python.exe" if sys.platform == "win32" else "python")
    if toolenv.is_ready(_HOME):  # made and checked by import before: collection asks often
        return python, ""
    with toolenv.locked(_HOME):
        if toolenv.is_ready(_HOME):  # another process made it while this one waited
            return python, ""
        made, why = toolenv.make(_HOME, ROS_MCP_PIN)
        if made is None:
            return None, why
        if not _has_ros_mcp(python):
            return None, f"{ROS_MCP_PIN} was installed in {_HOME} but cannot be imported"
        toolenv.mark_ready(_HOME)
    return python, ""
