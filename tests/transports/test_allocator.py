"""The allocator tuning behind ``rwt serve --heap-keep`` (B4/B6/B9) and ``--heap-trim`` (D75)."""

from __future__ import annotations

import platform
import subprocess
import sys

import anyio
import pytest

from rwt_transports.process import allocator
from rwt_transports.process.allocator import MMAP_THRESHOLD_MAX, trim_heap, tune_allocator
from tests.support.cli import rwt_serve


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
    reason="mallopt is glibc's",
)
def test_glibc_takes_both_thresholds() -> None:
    assert tune_allocator(64 * 1024 * 1024) is True
    # Asking for more than glibc allows is capped, not refused.
    assert tune_allocator(64 * 1024 * 1024, mmap_threshold=4 * MMAP_THRESHOLD_MAX) is True


def test_other_systems_are_left_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "platform", "darwin")
    allocator._libc_function.cache_clear()  # (it looks the C library up once)
    try:
        assert tune_allocator(64 * 1024 * 1024) is False
        assert trim_heap(0) is False
    finally:
        allocator._libc_function.cache_clear()


_HOLES = """
import sys
from rwt_transports.process.allocator import trim_heap

def rss() -> int:
    with open("/proc/self/statm", "rb") as statm:
        return int(statm.read().split()[1]) * 4096

blocks = [bytes(4000) for _ in range(20_000)]  # 80 MB of glibc heap (each over pymalloc's 512)
kept = blocks[::16]  # every 16th stays, the last one too: free cannot trim the heap's top
del blocks
before = rss()
given = trim_heap(0)
print(given, before - rss())
"""


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
    reason="malloc_trim is glibc's",
)
def test_trim_heap_gives_back_the_holes_free_keeps() -> None:
    # What ``rwt serve --heap-trim`` does every minute (D75): free heap between live
    # blocks, which ``free`` never gives back, leaves the process.
    done = subprocess.run(
        [sys.executable, "-c", _HOLES], capture_output=True, text=True, timeout=60, check=True
    )
    given, dropped = done.stdout.split()
    assert given == "True"
    assert int(dropped) > 40 * 1024 * 1024, done.stdout


@pytest.mark.anyio
async def test_serve_trims_its_heap_every_period() -> None:
    async with rwt_serve("--port", "0", "--heap-trim", "0.2", "--log-level", "debug") as (
        process,
        _,
    ):
        assert process.stderr is not None
        seen = b""
        with anyio.fail_after(30):
            while b"event=heap_trim" not in seen:
                seen += await process.stderr.receive()
    assert b"given_back=" in seen
