"""B23 smoke: one round of each MCP call through rwt's two fronts and ros-mcp.

Figures of one round mean nothing: only that every call of every front answered
without an error (``measure`` raises otherwise) and was counted.
"""

from __future__ import annotations

import anyio
import pytest

from tests.support.ros_mcp import ros_mcp_python

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from benchmarks import mcp_latency

ROS_MCP_PYTHON, _why = ros_mcp_python()  # its own environment: it holds mcp below 2 (D52)
if ROS_MCP_PYTHON is None:
    pytest.skip(f"ros-mcp 3.1.2 cannot run here: {_why}", allow_module_level=True)


def test_one_round_of_every_call_through_every_front() -> None:
    # 3 rounds of each front: 0.3 s apart stays within the listing cap's burst (5)
    results = anyio.run(mcp_latency.main, 1, str(ROS_MCP_PYTHON), 0.3)
    assert set(results) == {
        "rwt serve --mcp (HTTP)",
        "rwt serve --mcp (HTTP, 2026-07-28)",  # the current revision's client, both fronts
        "rwt mcp URL (stdio)",
        "rwt mcp URL (stdio, 2026-07-28)",
        "ros-mcp 3.1.2 (stdio)",
    }
    for calls in results.values():
        assert set(calls) == set(mcp_latency.CALLS)
        assert all(call["calls"] == 1 and call["p50_ms"] > 0 for call in calls.values())
    assert "| publish one message |" in mcp_latency.table(results)
