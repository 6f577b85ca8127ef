"""Keep large message buffers in the heap between messages (glibc only; benchmarks B4/B6/B9).

Every large message passes through several buffers of its size: the WebSocket
frame, the decoded payload, the encoded frame a subscriber gets. glibc serves
blocks above its mmap threshold with a fresh ``mmap`` and gives them back with
``munmap`` when freed, and trims the top of the heap once more than the trim
threshold is free there, so each message of a few megabytes page-faults its
buffers in again: measured here, a 4.8 MB JSON point cloud took 17 ms to take
in and re-encode, and 3.5 ms with the buffers kept. ``tune_allocator`` raises
both thresholds with ``mallopt(3)``: blocks up to ``mmap_threshold`` bytes come
from the heap, and up to ``trim_threshold`` bytes of freed heap stay in the
process for the next message (the price: that much RSS may stay after a burst).

``free`` only gives back the top of the heap, and only above the trim threshold:
freed memory between live blocks, and the heaps of other threads' arenas (rclpy's,
Fast DDS's, anyio's workers'), stay in the process: after a burst the RSS stays near
its peak. ``trim_heap`` gives them back (glibc's ``malloc_trim``), and ``keep_trimmed``
does that every ``--heap-trim`` seconds (decisions.md D75), the free top of the heap
that ``--heap-keep`` keeps included (resident once touched). At most one large message
a period then finds its buffers' pages given back and faults them in again.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import logging
import os
import sys
import time
from typing import Any

import anyio

__all__ = [
    "HEAP_KEEP_MIB",
    "HEAP_TRIM_S",
    "MMAP_THRESHOLD_MAX",
    "keep_trimmed",
    "trim_heap",
    "tune_allocator",
]

logger = logging.getLogger("rwt.allocator")

#: glibc's largest mmap threshold on 64-bit systems (``DEFAULT_MMAP_THRESHOLD_MAX``), bytes.
MMAP_THRESHOLD_MAX = 32 * 1024 * 1024
#: MiB of freed heap rwt's own processes keep by default (``rwt serve --heap-keep``,
#: ``rwt play``, ``rwt record``).
HEAP_KEEP_MIB = 64
#: Seconds between two trims of the heap by ``rwt serve`` (``--heap-trim``; D75).
HEAP_TRIM_S = 60.0
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3


def tune_allocator(trim_threshold: int, mmap_threshold: int = MMAP_THRESHOLD_MAX) -> bool:
    """Set glibc's trim and mmap thresholds for this process.

    Args:
        trim_threshold: bytes of free heap kept before the top is returned to
            the system.
        mmap_threshold: blocks at least this large get their own mapping; at
            most ``MMAP_THRESHOLD_MAX`` bytes.

    Returns:
        True when both were set; False on a system without glibc's ``mallopt``
        (macOS, Windows, musl), where nothing changes.
    """
    mallopt = _libc_function("mallopt")
    if mallopt is None:
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    done = bool(mallopt(_M_MMAP_THRESHOLD, min(mmap_threshold, MMAP_THRESHOLD_MAX)))
    done = bool(mallopt(_M_TRIM_THRESHOLD, trim_threshold)) and done
    logger.debug("event=mallopt trim=%d mmap=%d ok=%s", trim_threshold, mmap_threshold, done)
    return done


@functools.cache
def _libc_function(name: str) -> Any:
    """The C library's function ``name`` (ctypes), or None without it (not Linux, musl)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return getattr(ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6"), name)
    except (OSError, AttributeError):  # no libc found, or a libc without it
        return None


def trim_heap(keep: int) -> bool:
    """Give the process's free heap back to the system (glibc's ``malloc_trim(3)``).

    Every arena's free blocks give back their whole pages (``MADV_DONTNEED``: the
    addresses stay, the memory goes); the top of the main heap keeps ``keep`` bytes.
    It holds each arena's lock while it walks that arena's free blocks (under 0.1 ms
    on an idle ``rwt serve``; longer the more free blocks there are): call it from a
    worker thread (ctypes lets go of the GIL meanwhile).

    Args:
        keep: bytes of free memory left at the top of the main heap.

    Returns:
        True when memory was given back; False when none was, or on a system
        without glibc's ``malloc_trim``.
    """
    malloc_trim = _libc_function("malloc_trim")
    if malloc_trim is None:
        return False
    malloc_trim.argtypes = (ctypes.c_size_t,)
    malloc_trim.restype = ctypes.c_int
    return bool(malloc_trim(keep))


async def keep_trimmed(period_s: float) -> None:
    """Trim all free heap (``trim_heap(0)``) every ``period_s`` seconds, on a worker thread.

    Runs until cancelled; returns at once on a system without glibc's
    ``malloc_trim`` (nothing to do). The top of the heap keeps nothing: what
    ``--heap-keep`` holds for large messages is given back once a period too (D75).

    Args:
        period_s: seconds between two trims (``--heap-trim``, ``HEAP_TRIM_S``; D75).
    """
    if _libc_function("malloc_trim") is None:
        return
    while True:
        await anyio.sleep(period_s)
        before = _rss()
        given, took = await anyio.to_thread.run_sync(_timed_trim, 0)
        logger.debug(
            "event=heap_trim given_back=%s rss_mb=%.1f->%.1f took_ms=%.2f",
            given,
            before / 1e6,
            _rss() / 1e6,
            took * 1e3,
        )


def _timed_trim(keep: int) -> tuple[bool, float]:
    """``trim_heap(keep)`` and the seconds it took."""
    started = time.perf_counter()
    given = trim_heap(keep)
    return given, time.perf_counter() - started


def _rss() -> int:
    """The process's resident memory, bytes (``/proc/self/statm``; 0 where it cannot be read)."""
    try:
        with open("/proc/self/statm", "rb") as statm:
            return int(statm.read().split()[1]) * _PAGE
    except (OSError, ValueError, IndexError):
        return 0


_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096
