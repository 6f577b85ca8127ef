"""The MCP Inspector's command line, from a folder of its own made once with npm.

The Inspector (npm ``@modelcontextprotocol/inspector``) brings a web UI's
dependencies: 260 of the 294 packages tests/js would hold, and most of its
``npm ci`` time, for one test module (tests/agents/test_mcp_inspector.py).
So, as ros-mcp has its own Python environment (``toolenv``), the Inspector has
its own npm folder under ``~/.cache/rwt-tests``, installed from the pinned
lock file in tests/js/inspector (about 8 s, once) and reused after; ``.ci/run``
makes it before the suite. Without node or npm the caller skips.
"""

from __future__ import annotations

import functools
import json
import shutil
import subprocess
from pathlib import Path

from . import toolenv

__all__ = ["INSPECTOR_DIR", "inspector_bin"]

INSPECTOR_DIR = Path(__file__).resolve().parents[1] / "js" / "inspector"
"""Its ``package.json`` and ``package-lock.json`` (the pin)."""
_FILES = ("package.json", "package-lock.json")


def _pin() -> str:
    wanted = json.loads((INSPECTOR_DIR / "package.json").read_text())["dependencies"]
    return f"mcp-inspector-{wanted['@modelcontextprotocol/inspector']}"


def _current(home: Path) -> bool:
    """Whether ``home`` was installed from today's lock file (an earlier pin is redone)."""
    bin_ = home / "node_modules" / ".bin" / "mcp-inspector"
    return bin_.exists() and all(
        (home / name).is_file()
        and (home / name).read_bytes() == (INSPECTOR_DIR / name).read_bytes()
        for name in _FILES
    )


@functools.cache
def inspector_bin() -> tuple[Path | None, str]:
    """The ``mcp-inspector`` command: ``(path, "")``, or ``(None, why not)``."""
    home = toolenv.HOME / _pin()
    if _current(home):
        return home / "node_modules" / ".bin" / "mcp-inspector", ""
    npm = shutil.which("npm")
    if npm is None or shutil.which("node") is None:
        return None, "node and npm are needed for the MCP Inspector"
    shutil.rmtree(home, ignore_errors=True)
    home.mkdir(parents=True)
    for name in _FILES:
        shutil.copyfile(INSPECTOR_DIR / name, home / name)
    try:
        done = subprocess.run(
            [npm, "ci", "--no-audit", "--no-fund", "--prefix", str(home)],
            capture_output=True,
            text=True,
            check=False,
            timeout=600,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        done = None
        why = f"npm ci of the MCP Inspector failed: {exc}"
    else:
        why = f"npm ci of the MCP Inspector failed: {done.stderr.strip()[-300:]}"
    if done is None or done.returncode != 0:
        shutil.rmtree(home, ignore_errors=True)  # the next run tries again
        return None, why
    return home / "node_modules" / ".bin" / "mcp-inspector", ""
