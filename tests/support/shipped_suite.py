"""The shipped conformance suite, read once per test process (seven test files use it).

Each read parses every ``cases/*.toml``: a test process that collected the files
one by one read it seven times, in every xdist worker.
"""

from __future__ import annotations

from rwt_conformance import load_suite

SUITE = load_suite()
