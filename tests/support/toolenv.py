"""A virtual environment of its own for a tool the tests drive, made once with pip.

Tools whose pins clash with rwt's (ros-mcp holds mcp below 2; openapi-python-client
holds typer below 0.28) run from an environment of their own under
``~/.cache/rwt-tests``, as a user installs them (``pipx install ...``).

Every process of a run may ask for the same folder at once (each xdist worker at
collection, the controller ahead of them: ``tests/support/helper_envs.py``), so a
folder is made under a lock of its own (``locked``) and counts as made only once its
``READY`` file is written, the last step: a process that finds no such file waits for
the lock, then looks again, and never wipes a folder another process is making.
"""

from __future__ import annotations

import contextlib
import fcntl
import shutil
import subprocess
import sys
import venv
from collections.abc import Iterator
from pathlib import Path

__all__ = ["HOME", "READY", "bin_dir", "is_ready", "locked", "make", "mark_ready"]

HOME = Path.home() / ".cache" / "rwt-tests"
"""Where the environments live, one folder per pin (``ros-mcp-3.1.2``)."""
READY = ".rwt-tests-ready"
"""The file written in a folder once it is made and checked, and only then."""


def bin_dir(home: Path) -> Path:
    """The folder of an environment's executables."""
    return home / ("Scripts" if sys.platform == "win32" else "bin")


def is_ready(home: Path) -> bool:
    """Whether ``home`` was made to its end (its ``READY`` file is there)."""
    return (home / READY).is_file()


def mark_ready(home: Path) -> None:
    """Say that ``home`` is made: the last step of whoever makes it."""
    (home / READY).write_text("made by the rwt test suite\n")


@contextlib.contextmanager
def locked(home: Path) -> Iterator[None]:
    """Hold the lock of ``home`` (a file beside it): one process makes it at a time.

    The lock is ``flock``'s, so a process that dies holding it releases it.
    """
    home.parent.mkdir(parents=True, exist_ok=True)
    with open(home.parent / f"{home.name}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def make(home: Path, pin: str) -> tuple[Path | None, str]:
    """Make the environment at ``home`` with ``pin`` installed: ``(its python, "")``, or
    ``(None, why not)``; a failed one is removed, so that the next run tries again.

    The caller holds ``locked(home)`` and marks it ready once it has checked it.
    """
    python = bin_dir(home) / ("python.exe" if sys.platform == "win32" else "python")
    try:
        venv.create(home, with_pip=True, clear=True)
        install = [str(python), "-m", "pip", "install", "-q", pin]
        done = subprocess.run(install, capture_output=True, text=True, check=False, timeout=600)
    except (OSError, subprocess.TimeoutExpired) as exc:
        shutil.rmtree(home, ignore_errors=True)
        return None, f"could not make an environment for {pin}: {exc}"
    if done.returncode != 0:
        shutil.rmtree(home, ignore_errors=True)
        return None, f"pip install {pin} failed: {done.stderr.strip()[-300:]}"
    return python, ""
