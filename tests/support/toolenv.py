"""A virtual environment of its own for a tool the tests drive, made once with pip.

Tools whose pins clash with rwt's (ros-mcp holds mcp below 2; openapi-python-client
holds typer below 0.28) run from an environment of their own under
``~/.cache/rwt-tests``, as a user installs them (``pipx install ...``).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import venv
from pathlib import Path

__all__ = ["HOME", "bin_dir", "make"]

HOME = Path.home() / ".cache" / "rwt-tests"
"""Where the environments live, one folder per pin (``ros-mcp-3.1.2``)."""


def bin_dir(home: Path) -> Path:
    """The folder of an environment's executables."""
    return home / ("Scripts" if sys.platform == "win32" else "bin")


def make(home: Path, pin: str) -> tuple[Path | None, str]:
    """Make the environment at ``home`` with ``pin`` installed: ``(its python, "")``, or
    ``(None, why not)``; a failed one is removed, so that the next run tries again."""
    python = bin_dir(home) / ("python.exe" if sys.platform == "win32" else "python")
    try:
        venv.create(home, with_pip=True, clear=True)
        install = [str(python), "-m", "pip", "install", "-q", pin]
        done = subprocess.run(install, capture_output=True, text=True, check=False, timeout=600)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return None, f"could not make an environment for {pin}: {exc}"
    if done.returncode != 0:
        shutil.rmtree(home, ignore_errors=True)
        return None, f"pip install {pin} failed: {done.stderr.strip()[-300:]}"
    return python, ""
