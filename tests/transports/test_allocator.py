"""The allocator tuning behind ``rwt serve --heap-keep`` (benchmarks B4/B6/B9)."""

from __future__ import annotations

import platform
import sys

import pytest

from rwt_transports.process.allocator import MMAP_THRESHOLD_MAX, tune_allocator


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
    assert tune_allocator(64 * 1024 * 1024) is False
