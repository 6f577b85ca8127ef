"""The envelope's audit trail: a structured log line per event, and the last events kept.

Every clamp, rejection, rate drop, dead-man stop and approval (given, declined,
timed out, not possible) is an event: ``kind``, the client and its front end, the
topic (or service, action), the field, the value and the bound. Each is one line
on the ``rwt.safety`` logger, ``event=safety_<kind> client=... frontend=... topic=...
field=... value=... bound=... detail=...`` (docs/safety.md, D69).

What a client can repeat at its own rate (a clamp, a rejection, a rate drop) is an
episode per client, topic, field and kind: its first event is logged and kept, the
repeats are counted on it and summed up in the log at most every ``EVERY_S``, as the
access log does (``rwt_graph.ratelog``); the episode ends after ``QUIET_S`` without
one. The first event of an episode is also what the publisher is told of (one
warning status). A dead-man stop and an approval are logged each time: a client
cannot repeat them faster than the dead-man's time or a person answers.

``last`` keeps the newest ``KEEP`` events (episodes with their counts) for the
web console, newest last; memory stays bounded whatever clients do.
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from dataclasses import dataclass
from dataclasses import field as _field
from typing import TYPE_CHECKING

from ..ratelog import EpisodeLog

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["EVERY_S", "KEEP", "QUIET_S", "AuditTrail", "SafetyEvent"]

logger = logging.getLogger("rwt.safety")

KEEP = 100
"""Events the trail keeps for the console."""
QUIET_S = 5.0
"""Seconds without a repeat after which an episode (and its warning) ends."""
EVERY_S = 10.0
"""While an episode goes on, a log line with its count at most this often, seconds."""
REPEATED = frozenset({"clamp", "reject", "rate_drop"})
"""The kinds a client repeats at will: kept and logged once per episode."""


@dataclass
class SafetyEvent:
    """One event of the envelope (or one episode of repeats).

    Attributes:
        kind: ``clamp``, ``reject``, ``rate_drop``, ``deadman_stop``, ``approval_given``,
            ``approval_declined``, ``approval_timeout`` or ``approval_unavailable``.
        client: the client's id (``ws:127.0.0.1:50312#4``); the envelope's own for a stop.
        frontend: the front end it came through (``rosbridge``, ``foxglove``, ``http``, ``mcp``).
        target: the topic, service or action.
        field: the field (``linear.x``), or "".
        value: the value the client sent (a number, or its text), or None.
        bound: the bound (``[-0.5, 0.5]``), or "".
        detail: what happened (``sent 0.5``, ``quiet 0.5 s``, the tool).
        wall: when it (its episode) began, seconds since the epoch.
        count: events in its episode.
    """

    kind: str
    client: str
    frontend: str
    target: str
    field: str = ""
    value: object = None
    bound: str = ""
    detail: str = ""
    wall: float = _field(default_factory=time.time)
    count: int = 1

    def as_dict(self) -> dict[str, object]:
        """The event as JSON values (the console's ``/rwt/safety`` topic)."""
        value = self.value
        if isinstance(value, float) and math.isnan(value):  # NaN is not JSON
            value = "NaN"
        elif isinstance(value, float) and value in (float("inf"), float("-inf")):
            value = "Infinity" if value > 0 else "-Infinity"
        elif value is not None and not isinstance(value, int | float | str):
            value = str(value)
        return {
            "kind": self.kind,
            "client": self.client,
            "frontend": self.frontend,
            "target": self.target,
            "field": self.field,
            "value": value,
            "bound": self.bound,
            "detail": self.detail,
            "wall": self.wall,
            "count": self.count,
        }


class AuditTrail:
    """The log lines and the last events of one envelope (module text).

    Args:
        clock: monotonic seconds (the episodes' time).
        on_event: called with each event kept anew (not a counted repeat), e.g. to
            publish it for the console.
    """

    def __init__(
        self,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_event: Callable[[SafetyEvent], None] | None = None,
    ) -> None:
        self._clock = clock
        self._log = EpisodeLog(logger, every_s=EVERY_S, quiet_s=QUIET_S, clock=clock)
        self._last: deque[SafetyEvent] = deque(maxlen=KEEP)
        self._open: dict[tuple[str, str, str, str], tuple[SafetyEvent, float]] = {}
        self.on_event = on_event

    def record(self, event: SafetyEvent) -> bool:
        """Log and keep ``event``; a repeat of an open episode is counted on it.

        Returns:
            Whether it begins an episode (or is not of a repeated kind): the one
            its client is told of.
        """
        now = self._clock()
        key = (event.kind, event.client, event.target, event.field)
        first = True
        if event.kind in REPEATED:
            opened = self._open.get(key)
            first = opened is None or now - opened[1] > QUIET_S
            if first:
                self._forget_quiet(now)
                self._open[key] = (event, now)
            else:
                kept = opened[0]  # type: ignore[index]  # not first: there is one
                kept.count += 1
                kept.value = event.value
                self._open[key] = (kept, now)
            self._log.log(logging.WARNING, "|".join(key), _LINE, *_fields(event), now=now)
        else:
            logger.warning(_LINE, *_fields(event))
        if first:
            self._last.append(event)
            if self.on_event is not None:
                self.on_event(event)
        return first

    def last(self) -> list[SafetyEvent]:
        """The newest ``KEEP`` events (episodes with their counts), oldest first."""
        return list(self._last)

    def _forget_quiet(self, now: float) -> None:
        """Drop the ended episodes, so that the open ones stay as few as the live ones."""
        if len(self._open) < KEEP:
            return
        for key, (_, last) in list(self._open.items()):
            if now - last > QUIET_S:
                del self._open[key]
        while len(self._open) >= KEEP:  # all still open: the oldest goes
            del self._open[next(iter(self._open))]


_LINE = "event=safety_%s client=%s frontend=%s target=%s field=%s value=%r bound=%s detail=%r"


def _fields(event: SafetyEvent) -> tuple[object, ...]:
    return (
        event.kind,
        event.client,
        event.frontend,
        event.target,
        event.field or "-",
        event.value,
        event.bound.replace(" ", "") or "-",
        event.detail,
    )
