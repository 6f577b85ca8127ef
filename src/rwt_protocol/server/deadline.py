"""A topic's deadline, watched for one client: one warning per episode (protocol 2.1.0; D65).

A subscription with a deadline (``requested deadline missed`` in ROS 2) and a
publisher whose advertisement asked one (``offered deadline missed``) are both
told when their topic sends nothing for that long: once, and again only after
the next message ends the episode. The check runs at most every
``DEADLINE_CHECK_S``, so a deadline of 1 ms costs a timer every 100 ms, not a
thousand a second.

Time is the ``now`` the session's timers give; nothing here reads a clock.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..runtime.timers import Timer

__all__ = ["DEADLINE_CHECK_S", "DeadlineWatch", "Schedule"]

DEADLINE_CHECK_S = 0.1
"""The shortest time between two checks of a deadline, seconds (D65): a deadline of
1 ms costs a timer every 100 ms at most, not a thousand a second: a client's 1,000
subscriptions (``--max-subscriptions``) cost 10,000 checks a second at most."""

Schedule = Callable[[float, Callable[[float], None]], "Timer"]
"""Runs a callback with ``now`` at a monotonic deadline (``Session.call_at``)."""


class DeadlineWatch:
    """Calls ``missed`` once per episode of ``deadline_s`` without a message on a topic (D65).

    Args:
        schedule: the session's timers.
        missed: called when the topic missed the deadline (the client's warning).
    """

    __slots__ = (
        "_deadline_s",
        "_latest",
        "_missed",
        "_missed_after",
        "_schedule",
        "_since",
        "_timer",
    )

    def __init__(self, schedule: Schedule, missed: Callable[[], None]) -> None:
        self._schedule = schedule
        self._missed = missed
        self._deadline_s = math.inf
        self._latest: Callable[[], float] | None = None
        self._since = 0.0
        self._timer: Timer | None = None
        self._missed_after: float | None = None  # the last message before a missed deadline

    def arm(self, deadline_s: float, latest: Callable[[], float], since: float) -> None:
        """Watch ``deadline_s`` (inf: none) from now on; (re)arms the check.

        Args:
            deadline_s: the deadline in force, seconds.
            latest: the monotonic time of the topic's latest message (``-inf``
                before any; ``rwt_graph.topic_qos``).
            since: when the client started waiting (its registration), monotonic
                seconds: a topic that never sent anything misses from there.
        """
        self.cancel()
        self._deadline_s, self._latest, self._since = deadline_s, latest, since
        if math.isinf(deadline_s):
            return
        last = max(latest(), since)
        self._timer = self._schedule(max(last + deadline_s, since + DEADLINE_CHECK_S), self._due)

    def cancel(self) -> None:
        """Stop watching (the client no longer waits on the topic)."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _due(self, now: float) -> None:
        """Warn once if no message came within the deadline; check again."""
        self._timer = None
        deadline, latest = self._deadline_s, self._latest
        if math.isinf(deadline) or latest is None:
            return
        last = max(latest(), self._since)
        if now - last >= deadline:
            if self._missed_after != last:
                self._missed_after = last  # one warning per episode: until a message comes
                self._missed()
            due = now + max(deadline, DEADLINE_CHECK_S)
        else:
            due = max(last + deadline, now + DEADLINE_CHECK_S)
        self._timer = self._schedule(due, self._due)
