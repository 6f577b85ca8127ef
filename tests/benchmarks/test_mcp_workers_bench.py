"""B24 smoke: one short round against each server, plain and ``--workers 2``.

Figures of one short round mean nothing: only that both servers answered every
raw 2026-07-28 call of the generator with a result and the table shows them.
"""

from __future__ import annotations

import os

import pytest

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from benchmarks import mcp_workers


@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="--workers: Linux only")
def test_one_round_against_each_server() -> None:
    runs = mcp_workers.main(0.5, 1, 4, warm_up_s=0.1)
    assert list(runs) == ["rwt serve --mcp", "rwt serve --mcp --workers 2"]
    for bursts in runs.values():
        (burst,) = bursts
        assert burst.calls > 0 and burst.errors == 0
        assert burst.server_cpu_s > 0
    assert "| rwt serve --mcp --workers 2 |" in mcp_workers.table(runs)
