"""The MCP Inspector's command line, from a folder of its own made once with npm.

The Inspector (npm ``@modelcontextprotocol/inspector``) brings a web UI's
dependencies: 260 of the 294 packages tests/js would hold, and most of its
``npm ci`` time, for one test module (tests/agents/test_mcp_inspector.py).
So, as ros-mcp has its own Python environment (``toolenv``), the Inspector has
its own npm folder under ``~/.cache/rwt-tests``, installed from the pinned
lock file in tests/js/inspector (about 8 s, once) and reused after; the xdist
controller starts it before its workers (``helper_envs``). Without node or npm the caller skips.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

from .npm_folder import npm_folder

__all__ = ["INSPECTOR_DIR", "inspector_bin"]

INSPECTOR_DIR = Path(__file__).resolve().parents[1] / "js" / "inspector"
"""Its ``package.json`` and ``package-lock.json`` (the pin)."""
_BIN = "node_modules/.bin/mcp-inspector"


@functools.cache
def inspector_bin() -> tuple[Path | None, str]:
    """The ``mcp-inspector`` command: ``(path, "")``, or ``(None, why not)``."""
    wanted = json.loads((INSPECTOR_DIR / "package.json").read_text())["dependencies"]
    pin = f"mcp-inspector-{wanted['@modelcontextprotocol/inspector']}"
    home, why = npm_folder(INSPECTOR_DIR, pin, _BIN)
    return (None, why) if home is None else (home / _BIN, "")
