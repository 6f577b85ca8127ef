"""B25 smoke: a short flood beside both bystanders.

Figures of a one-second flood mean nothing: only that both bystanders (rosbridge and
Foxglove) timed round trips in both phases, and the flood's requests were answered.
"""

from __future__ import annotations

import pytest

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from benchmarks import mcp_flood


def test_a_short_flood_is_timed_by_both_bystanders() -> None:
    phases, tally = mcp_flood.main(1.0, 1.0, 2, 1)
    assert set(phases) == {"rosbridge", "Foxglove"}
    for both in phases.values():
        assert both["idle"].calls > 0 and both["flood"].calls > 0
    assert tally["200 result"] > 0 and tally["listen 200"] == 1
    assert "| Foxglove |" in mcp_flood.table(phases)
