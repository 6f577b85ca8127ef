"""The audit trail's memory: bounded whatever clients do, episodes as JSON for the console.

``AuditTrail`` (``rwt.safety``) keeps at most ``KEEP`` open episodes: past that, the
ended ones go, then the oldest, whose client is told again at its next repeat rather
than the trail growing with each client (docs/safety.md, D69). ``SafetyEvent.as_dict``
is what ``/rwt/safety`` carries: JSON values only, whatever value a client sent.
"""

from __future__ import annotations

import json
import math

from rwt.safety import AuditTrail, SafetyEvent
from rwt_graph.safety.audit import KEEP, QUIET_S


class Clock:
    """Monotonic seconds, moved by hand."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _clamp(client: int) -> SafetyEvent:
    return SafetyEvent("clamp", f"ws:10.0.0.1:{client}#1", "rosbridge", "/cmd_vel", "linear.x", 2.0)


def test_open_episodes_stay_bounded_the_oldest_told_again() -> None:
    clock = Clock()
    trail = AuditTrail(clock=clock)  # no on_event: nothing but the log and ``last``
    assert all(trail.record(_clamp(client)) for client in range(KEEP))
    clock.now = 1.0
    assert not trail.record(_clamp(1))  # a repeat within its episode: counted, not told
    assert trail.record(_clamp(KEEP))  # one client too many: the oldest episode goes
    assert trail.record(_clamp(0))  # so its next repeat is told again
    assert not trail.record(_clamp(2))
    counts = {event.client: event.count for event in trail.last()}
    assert counts["ws:10.0.0.1:2#1"] == 2 and counts["ws:10.0.0.1:0#1"] == 1
    assert "ws:10.0.0.1:1#1" not in counts  # the trail keeps the newest KEEP events
    clock.now = 1.0 + QUIET_S + 1
    assert trail.record(_clamp(KEEP + 1))  # the ended episodes go at once
    assert trail.record(_clamp(3))
    assert len(trail.last()) == KEEP


def test_an_event_is_json_whatever_its_value() -> None:
    values = [math.nan, math.inf, -math.inf, 2.5, 7, "fast", None, b"\x01", (1, 2)]
    shown = [
        SafetyEvent("reject", "c", "http", "/t", "x", value).as_dict()["value"] for value in values
    ]
    assert shown == ["NaN", "Infinity", "-Infinity", 2.5, 7, "fast", None, "b'\\x01'", "(1, 2)"]
    json.dumps(shown, allow_nan=False)
