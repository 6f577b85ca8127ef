"""B23 smoke: one round of each MCP call through rwt's two fronts and ros-mcp.

Figures of one round mean nothing: only that every call of every front answered
without an error (``measure`` raises otherwise) and was counted.
"""

from __future__ import annotations

import importlib.util

import anyio
import pytest

if importlib.util.find_spec("ros_mcp") is None:  # not imported here: it runs in its own process
    pytest.skip("ros-mcp is not installed (the test extra)", allow_module_level=True)

from benchmarks import mcp_latency


def test_one_round_of_every_call_through_every_front() -> None:
    results = anyio.run(mcp_latency.main, 1)
    assert set(results) == {
        "rwt serve --mcp (HTTP)",
        "rwt mcp URL (stdio)",
        "ros-mcp 3.1.2 (stdio)",
    }
    for calls in results.values():
        assert set(calls) == set(mcp_latency.CALLS)
        assert all(call["calls"] == 1 and call["p50_ms"] > 0 for call in calls.values())
    assert "| publish one message |" in mcp_latency.table(results)
