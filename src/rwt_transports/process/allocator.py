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
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import sys

__all__ = ["HEAP_KEEP_MIB", "MMAP_THRESHOLD_MAX", "tune_allocator"]

logger = logging.getLogger("rwt.allocator")

#: glibc's largest mmap threshold on 64-bit systems (``DEFAULT_MMAP_THRESHOLD_MAX``), bytes.
MMAP_THRESHOLD_MAX = 32 * 1024 * 1024
#: MiB of freed heap rwt's own processes keep by default (``rwt serve --heap-keep``,
#: ``rwt play``, ``rwt record``).
HEAP_KEEP_MIB = 64
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
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):  # no libc found, or a libc without mallopt
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    done = bool(mallopt(_M_MMAP_THRESHOLD, min(mmap_threshold, MMAP_THRESHOLD_MAX)))
    done = bool(mallopt(_M_TRIM_THRESHOLD, trim_threshold)) and done
    logger.debug("event=mallopt trim=%d mmap=%d ok=%s", trim_threshold, mmap_threshold, done)
    return done
