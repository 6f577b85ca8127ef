"""npm folders the tests install once under ``~/.cache/rwt-tests``, from a pinned lock file.

Some real clients bring many npm packages for one test module (the MCP Inspector, a
web UI's worth; the MCP Apps host, with a bundler): each has its lock file in a folder
of tests/js and is installed with ``npm ci`` into a folder of its own under
``~/.cache/rwt-tests``, named by its pin, once, and reused while its files are the
same (an edited lock file installs again). The xdist controller starts them before
its workers (``helper_envs``), so that their installs overlap the workers' start.
Without node or npm the caller skips.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

from . import toolenv

__all__ = ["npm_folder"]

LOCK_FILES = ("package.json", "package-lock.json")


def _current(home: Path, source: Path, files: tuple[str, ...], ready: str) -> bool:
    """Whether ``home`` was made to its end from ``source``'s files as they are now."""
    return (
        toolenv.is_ready(home)
        and (home / ready).exists()
        and all(
            (home / name).is_file() and (home / name).read_bytes() == (source / name).read_bytes()
            for name in files
        )
    )


def npm_folder(
    source: Path,
    pin: str,
    ready: str,
    *,
    files: tuple[str, ...] = LOCK_FILES,
    build: Callable[[Path], str | None] | None = None,
) -> tuple[Path | None, str]:
    """The installed folder of ``source``'s npm packages: ``(path, "")`` or ``(None, why)``.

    Args:
        source: the folder with ``package.json`` and ``package-lock.json`` (and ``files``).
        pin: the folder's name under ``~/.cache/rwt-tests`` (its pinned versions).
        ready: a path in the folder that exists once it is installed (and built).
        files: the files of ``source`` copied there (a change installs again).
        build: run after ``npm ci`` in the folder; a text is why it failed.
    """
    home = toolenv.HOME / pin
    if _current(home, source, files, ready):
        return home, ""
    npm = shutil.which("npm")
    if npm is None or shutil.which("node") is None:
        return None, f"node and npm are needed for {source.name}"
    with toolenv.locked(home):  # every xdist worker may ask at once (toolenv)
        if _current(home, source, files, ready):
            return home, ""
        why = _install(npm, source, home, files, build)
        if why or not (home / ready).exists():
            shutil.rmtree(home, ignore_errors=True)  # the next run tries again
            return None, why or f"{source.name}: {ready} was not made"
        toolenv.mark_ready(home)
    return home, ""


def _install(
    npm: str,
    source: Path,
    home: Path,
    files: tuple[str, ...],
    build: Callable[[Path], str | None] | None,
) -> str:
    """``npm ci`` of ``source``'s files in a new ``home``, then ``build``: why it failed, or ""."""
    shutil.rmtree(home, ignore_errors=True)
    home.mkdir(parents=True)
    for name in files:
        shutil.copyfile(source / name, home / name)
    try:
        done = subprocess.run(
            [npm, "ci", "--no-audit", "--no-fund", "--prefix", str(home)],
            capture_output=True,
            text=True,
            check=False,
            timeout=600,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"npm ci of {source.name} failed: {exc}"
    if done.returncode != 0:
        return f"npm ci of {source.name} failed: {done.stderr.strip()[-300:]}"
    return (build(home) or "") if build is not None else ""
