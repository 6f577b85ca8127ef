"""The MCP Apps host of the browser tests, from a folder of its own made once with npm.

``@modelcontextprotocol/ext-apps``' AppBridge (the host side of MCP Apps) and the
official MCP client, bundled by esbuild into ``host.bundle.js`` for Chromium
(tests/js/apphost: ``host.mjs``, ``host.html``, the pinned lock file), installed
under ``~/.cache/rwt-tests`` once (``npm_folder``); the xdist controller starts it
before its workers (``helper_envs``). Without node or npm the caller skips.
"""

from __future__ import annotations

import functools
import json
import subprocess
from pathlib import Path

from .npm_folder import LOCK_FILES, npm_folder

__all__ = ["APPHOST_DIR", "app_host"]

APPHOST_DIR = Path(__file__).resolve().parents[1] / "js" / "apphost"
"""The host's sources and its pin."""
_FILES = (*LOCK_FILES, "host.mjs", "host.html")
BUNDLE = "host.bundle.js"


def _bundle(home: Path) -> str | None:
    """Bundle ``host.mjs`` and its packages for the browser; why it failed, or None."""
    esbuild = home / "node_modules" / ".bin" / "esbuild"
    args = ["host.mjs", "--bundle", "--format=esm", "--platform=browser", f"--outfile={BUNDLE}"]
    try:
        done = subprocess.run(
            [str(esbuild), *args],
            check=False,
            cwd=home,
            capture_output=True,
            text=True,
            timeout=120,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"esbuild failed: {exc}"
    return None if done.returncode == 0 else f"esbuild failed: {done.stderr.strip()[-300:]}"


@functools.cache
def app_host() -> tuple[Path | None, str]:
    """The folder serving ``host.html`` and its bundle: ``(path, "")``, or ``(None, why not)``."""
    wanted = json.loads((APPHOST_DIR / "package.json").read_text())["dependencies"]
    pin = f"mcp-app-host-{wanted['@modelcontextprotocol/ext-apps']}"
    return npm_folder(APPHOST_DIR, pin, BUNDLE, files=_FILES, build=_bundle)
