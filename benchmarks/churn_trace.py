"""``rwt serve`` under tracemalloc, for B26's leak hunts (``python -m benchmarks.churn --trace N``).

``python -m benchmarks.churn_trace FRAMES DIR serve ...`` runs the ``rwt`` command with
the arguments after ``DIR``. Each SIGUSR2 writes, in ``DIR``, ``snap-<k>.pickle`` (a
tracemalloc snapshot, ``Snapshot.load`` reads it) and ``types-<k>.json`` (the count of
live objects the garbage collector tracks, by type, after a collection) and
``heap-<k>.json`` (where the process's memory is: ``VmRSS``, glibc's ``mallinfo2``
of every arena, pymalloc's arenas and blocks, tracemalloc's traced total; at the last,
``VmRSS`` again after glibc's ``malloc_trim``: how much was free heap), then
``done-<k>`` when all are whole. The first one starts tracemalloc (``FRAMES`` frames a
traceback; 0: no tracemalloc, no snapshots) before its snapshot: so the server starts at
its usual speed (under tracemalloc its imports took minutes on a loaded 2-core machine),
and a later snapshot holds exactly what was allocated since the first and is still
alive. The snapshots are
taken on the server's event loop thread, which stops while one is written: a debugging
run's figures of time mean nothing. tracemalloc keeps its own tables with the C
allocator, so under it glibc's figures grow with the traces: ``FRAMES`` 0 reads the
heap as it is (and pymalloc's figures, which tracemalloc's hooks hide).
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import json
import os
import re
import signal
import sys
import tempfile
import tracemalloc
import weakref
from collections import Counter
from pathlib import Path
from typing import Any

__all__ = ["main"]


_MALLINFO2 = ("arena", "ordblks", "smblks", "hblks", "hblkhd")
_MALLINFO2 += ("usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in _MALLINFO2]


def _glibc() -> dict[str, int]:
    """glibc's ``mallinfo2`` (every arena): ``arena`` bytes from the system (brk and arenas'
    heaps), ``uordblks`` of them in use, ``fordblks`` free, ``hblkhd`` mmapped blocks."""
    try:
        mallinfo2 = ctypes.CDLL("libc.so.6").mallinfo2
    except (OSError, AttributeError):
        return {}
    mallinfo2.restype = _MallInfo2
    info = mallinfo2()
    return {name: getattr(info, name) for name, _ in _MallInfo2._fields_}


def _pymalloc() -> dict[str, int]:
    """pymalloc's arenas now and bytes in its used and free blocks (``_debugmallocstats``,
    which writes to the C ``stderr``: read back from a file)."""
    with tempfile.TemporaryFile() as out:
        saved = os.dup(2)
        sys.stderr.flush()
        os.dup2(out.fileno(), 2)
        try:
            sys._debugmallocstats()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        out.seek(0)
        text = out.read().decode("ascii", "replace")
    wanted = {
        "arenas": r"# arenas allocated current\s*=\s*([\d,]+)",
        "used_bytes": r"# bytes in allocated blocks\s*=\s*([\d,]+)",
        "free_bytes": r"# bytes in available blocks\s*=\s*([\d,]+)",
    }
    found = {k: re.search(p, text) for k, p in wanted.items()}
    return {k: int(m[1].replace(",", "")) for k, m in found.items() if m}


def _weakrefs(objects: list[object]) -> Counter[str]:
    """Weak references by what they point to (``weakref->TYPE``, ``weakref->dead``) and,
    for a sample of 200, by the type of what holds them (``weakref<-TYPE``)."""
    refs = [obj for obj in objects if type(obj) is weakref.ReferenceType]
    found: Counter[str] = Counter()
    for ref in refs:
        target = ref()
        found["weakref->" + ("dead" if target is None else type(target).__qualname__)] += 1
    for ref in refs[-200:]:
        for holder in gc.get_referrers(ref):
            if holder is not refs and holder is not objects:
                found["weakref<-" + type(holder).__qualname__] += 1
    for obj in objects:  # rclpy's callback groups keep a weak reference per entity
        entities = getattr(obj, "entities", None) if type(obj).__name__.endswith("Group") else None
        if isinstance(entities, set):
            found[f"{type(obj).__qualname__}.entities"] += len(entities)
            found[f"{type(obj).__qualname__}.entities dead"] += sum(
                1 for r in entities if r() is None
            )
    return found


def _malloc_trim() -> None:
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6").malloc_trim(0)


def _rss() -> int:
    with open("/proc/self/status", encoding="ascii") as f:
        return next(int(ln.split()[1]) * 1024 for ln in f if ln.startswith("VmRSS:"))


def _dump(folder: Path, taken: list[int], frames: int) -> None:
    k = len(taken)
    taken.append(k)
    gc.collect()
    objects = gc.get_objects()
    types = Counter(type(obj).__qualname__ for obj in objects)
    types.update(_weakrefs(objects))
    (folder / f"types-{k}.json").write_text(json.dumps(dict(types.most_common())))
    heap = {
        "rss": _rss(),
        "glibc": _glibc(),
        "pymalloc": _pymalloc(),
        "traced": tracemalloc.get_traced_memory()[0],
    }
    if k:  # the last dump: how much of RSS is free heap glibc can give back
        _malloc_trim()
        heap["rss_after_trim"] = _rss()
    (folder / f"heap-{k}.json").write_text(json.dumps(heap))
    if frames:
        if not tracemalloc.is_tracing():
            tracemalloc.start(frames)
        tracemalloc.take_snapshot().dump(str(folder / f"snap-{k}.pickle"))
    (folder / f"done-{k}").touch()


def main() -> None:
    """See the module's docstring."""
    frames, folder, *rest = sys.argv[1:]
    taken: list[int] = []

    def on_signal(_signum: int, _frame: Any) -> None:
        _dump(Path(folder), taken, int(frames))

    signal.signal(signal.SIGUSR2, on_signal)
    sys.argv = ["rwt", *rest]
    from rwt._cli import main as rwt_main  # noqa: PLC0415 (the handler stands first)

    rwt_main()


if __name__ == "__main__":
    main()
