"""The attack replays' smoke form: one cheap class, tiny durations (benchmarks/attacks.py).

Class 10 (hostile MCP bodies) for a second against a real ``rwt serve --mcp``: the
figures of so short a run mean nothing, only that each part of the replay ran (the
server, the bystander's round trips in both phases, /proc, the attacker's tally)
and that the server's answers are what D41 says: 400 with a JSON-RPC parse error,
no traceback. The latency verdict is not asserted (it is a timing).
"""

from __future__ import annotations

import anyio
import pytest

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")
pytest.importorskip("aiortc", reason="aiortc is not installed (the webrtc extra)")

from benchmarks.attack_kit import replay
from benchmarks.attacks import all_attacks


def test_one_class_replays_with_its_figures_and_outcome() -> None:
    (hostile,) = [a for a in all_attacks() if a.number == "10"]
    result = anyio.run(lambda: replay(hostile, scale=0.1))
    assert result.baseline.calls > 0 and result.attack.calls > 0
    assert result.rss_peak_mb >= result.rss_start_mb > 0
    assert result.outcome["requests"] > 0
    assert result.outcome["by status and JSON-RPC code"] == {
        "400 -32700": result.outcome["requests"]
    }
    assert result.rights_ok and result.log_tracebacks == 0
    assert result.verdict in {"held", "NOT held"}


def test_every_class_says_how_it_was_scaled() -> None:
    numbers = [a.number for a in all_attacks()]
    assert numbers[:3] == ["1", "2", "3"] and "19" in numbers
    assert all(a.scaled and a.seconds <= 20 for a in all_attacks())
