"""The suite's test files, longest first, for xdist's ``--dist loadfile``.

xdist hands out whole files in the order collection gives them, and by default sorts
them by their number of tests, most first. So the files of one or two long tests (a
benchmark's smoke run, a real browser, a ROS 2 graph) went last, and a 20 s file
begun in the last minute held the run open while the other workers idled. The suite
runs with ``--no-loadscope-reorder`` instead, and ``tests/conftest.py`` orders the files
by how long each took in a recent run (``file_seconds.json``, wall seconds on this
2-core machine): the longest start first and the short ones fill in at the end. A
file not listed counts as ``UNKNOWN_S``. Every worker orders alike (xdist checks
that they collected the same list).

Refresh the figures from a run with ``--durations=0``::

    python -m pytest --durations=0 > run.log
    python -m tests.support.file_order run.log
"""

from __future__ import annotations

import functools
import json
import re
import sys
from collections import Counter
from pathlib import Path

__all__ = ["UNKNOWN_S", "file_seconds", "from_durations"]

FIGURES = Path(__file__).with_name("file_seconds.json")
UNKNOWN_S = 1.0
"""Seconds assumed for a file the figures do not name (a new one)."""
_LINE = re.compile(r"^(\d+(?:\.\d+)?)s (?:setup|call|teardown)\s+(\S+?)::")


@functools.cache
def file_seconds() -> dict[str, float]:
    """Each test file's seconds (its path from the repository root); {} without figures."""
    try:
        figures = json.loads(FIGURES.read_text())
    except (OSError, ValueError):
        return {}
    return {str(path): float(seconds) for path, seconds in figures.items()}


def from_durations(log: str) -> dict[str, float]:
    """Seconds per file from pytest's ``--durations=0`` report (setup, call, teardown)."""
    total: Counter[str] = Counter()
    for line in log.splitlines():
        match = _LINE.match(line.strip())
        if match:
            total[match[2]] += float(match[1])
    return {path: round(seconds, 1) for path, seconds in sorted(total.items())}


if __name__ == "__main__":
    figures = from_durations(Path(sys.argv[1]).read_text())
    FIGURES.write_text(json.dumps(figures, indent=0) + "\n")
    print(f"{len(figures)} files, {sum(figures.values()):.0f} s")
