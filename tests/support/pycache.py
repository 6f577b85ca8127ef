"""Bytecode under a ``pycache_prefix`` that reuses the installed modules' own bytecode.

Under ``PYTHONDONTWRITEBYTECODE`` the suite keeps bytecode under
``.pytest_cache/pycache`` (tests/conftest.py). A prefix applies to every module,
though: Python then ignores the ``__pycache__`` that the standard library and pip
installed beside their sources, so on a fresh clone each test worker and its warm
``rwt`` compiled the same thousands of them at once (about 7 s of CPU a process,
twice the cost of collecting the suite). ``reuse_installed()`` makes this process
look for bytecode of a file outside this checkout in the prefix first and, where it
has none yet, link it there from the file's own ``__pycache__``: Python checks it
against the source as always (a stale one is compiled again and written over the
link, in the prefix), and the processes the tests start find the links too.

Only the standard library: this runs before the process imports anything else.
"""

from __future__ import annotations

import contextlib
import os
import py_compile
import sys
import threading
from collections.abc import Iterable
from fnmatch import fnmatch
from importlib import _bootstrap_external  # type: ignore[attr-defined]
from pathlib import Path
from typing import Any

#: This checkout: its files' bytecode is the prefix's own.
CHECKOUT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def reuse_installed() -> None:
    """In this process, link installed modules' bytecode into ``sys.pycache_prefix``."""
    original = _bootstrap_external.cache_from_source
    if getattr(original, "reuses_installed", False):
        return
    ours = CHECKOUT + os.sep

    def cache_from_source(
        path: str, debug_override: bool | None = None, *, optimization: object = None
    ) -> str:
        cached: str = original(path, debug_override, optimization=optimization)
        prefix = sys.pycache_prefix
        if not prefix or os.fspath(path).startswith(ours) or os.path.lexists(cached):
            return cached
        # the same file name as without a prefix, in the source's own __pycache__
        installed = os.path.join(
            os.path.dirname(os.fspath(path)), "__pycache__", os.path.basename(cached)
        )
        if os.path.isfile(installed):
            with contextlib.suppress(OSError):  # another process linked it first
                os.makedirs(os.path.dirname(cached), exist_ok=True)
                os.symlink(installed, cached)
        return cached

    cache_from_source.reuses_installed = True  # type: ignore[attr-defined]
    _bootstrap_external.cache_from_source = cache_from_source


def link_loaded() -> None:
    """Link the bytecode of the installed modules loaded so far (before ``reuse_installed``)."""
    for module in list(sys.modules.values()):
        source = getattr(module, "__file__", None)
        if isinstance(source, str) and source.endswith(".py"):
            with contextlib.suppress(ValueError):
                _bootstrap_external.cache_from_source(source)


def _fresh(pyc: str, source: os.stat_result) -> bool:
    """Whether ``pyc`` is this interpreter's timestamp pyc of ``source`` (as import checks it)."""
    try:
        with open(pyc, "rb") as file:
            header = file.read(16)
    except OSError:
        return False
    return header == b"".join(
        [
            _bootstrap_external.MAGIC_NUMBER,
            bytes(4),
            (int(source.st_mtime) & 0xFFFFFFFF).to_bytes(4, "little"),
            (source.st_size & 0xFFFFFFFF).to_bytes(4, "little"),
        ]
    )


def prime(config: Any, folders: Iterable[str], tests: Iterable[str]) -> None:
    """Write this checkout's bytecode once, in the xdist controller, before its workers start.

    The workers import the whole suite at collection, all at the same time: on a fresh
    clone each compiled ``src`` and rewrote the asserts of every test module itself
    (about 7 s of CPU a worker, the same work four times over). Here it is done once
    and the workers read it: ``folders``' modules compiled as Python would; their test
    modules (those under one of ``tests``) and conftest files, and the plugin modules
    this process rewrote before it could write them, as pytest's assertion rewriting
    writes them. An up-to-date file is left as it is; one that fails here is left to
    the workers, which report it.
    """
    try:
        from _pytest.assertion import rewrite  # noqa: PLC0415 - pytest's processes only

        state = config.stash[rewrite.assertstate_key]
        hooks = [f for f in sys.meta_path if isinstance(f, rewrite.AssertionRewritingHook)]
        plugins = [str(p) for h in hooks for p in h._rewritten_names.values()]
    except (ImportError, AttributeError, KeyError):  # another pytest: the workers write them
        return
    patterns = config.getini("python_files")
    under = tuple(os.path.abspath(t.partition("::")[0]) for t in tests)
    sources = [(path, True) for path in plugins if not path.startswith(CHECKOUT + os.sep)]
    for folder in folders:
        for root, dirs, files in os.walk(folder):
            dirs[:] = [d for d in dirs if not d.startswith(".") and d not in _NOT_SOURCES]
            for name in files:
                path = os.path.join(root, name)
                if not name.endswith(".py"):
                    continue
                if name != "conftest.py" and any(fnmatch(name, p) for p in patterns):
                    if any(path == u or path.startswith(u + os.sep) for u in under):
                        sources.append((path, True))
                else:
                    sources.append((path, name == "conftest.py"))
    stale: list[tuple[Path, str, bool]] = []
    for path, rewritten in sources:
        source = Path(path)
        if rewritten:
            pyc = str(rewrite.get_cache_dir(source) / (source.name[:-3] + rewrite.PYC_TAIL))
        else:
            pyc = _bootstrap_external.cache_from_source(path)
        with contextlib.suppress(OSError):
            if not _fresh(pyc, source.stat()):
                stale.append((source, pyc, rewritten))
    # on every core (the workers wait for it): forked while this process has no other thread
    forks = hasattr(os, "fork") and _single_threaded() and len(stale) > 50
    shares = min(os.cpu_count() or 1, 4) if forks else 1
    children = []
    for share in range(1, shares):
        pid = os.fork()
        if pid == 0:
            try:
                _write(stale[share::shares], config, state)
            finally:
                os._exit(0)
        children.append(pid)
    _write(stale[::shares], config, state)
    for pid in children:
        os.waitpid(pid, 0)


def _single_threaded() -> bool:
    """Whether this process has one thread (native ones too, where /proc says): safe to fork."""
    try:
        return len(os.listdir("/proc/self/task")) == 1
    except OSError:
        return threading.active_count() == 1


def _write(stale: list[tuple[Path, str, bool]], config: Any, state: Any) -> None:
    """Compile or rewrite each of ``stale`` into its pyc file (``prime``)."""
    from _pytest.assertion import rewrite  # noqa: PLC0415 - pytest's processes only

    for source, pyc, rewritten in stale:
        try:
            if rewritten:
                os.makedirs(os.path.dirname(pyc), exist_ok=True)
                stat, code = rewrite._rewrite_test(source, config)
                rewrite._write_pyc(state, code, stat, Path(pyc))
            else:
                py_compile.compile(str(source), pyc, doraise=True, invalidation_mode=_TIMESTAMP)
        except Exception:  # one that fails to compile: the workers say why
            continue


_TIMESTAMP = py_compile.PycInvalidationMode.TIMESTAMP
#: Folders of no module the suite imports.
_NOT_SOURCES = frozenset({"__pycache__", "node_modules"})
