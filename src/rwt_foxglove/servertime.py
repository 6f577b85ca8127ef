"""The ``time`` capability: a bag's clock as Foxglove server time (docs/foxglove.md).

While a bag plays into the graph (``rwt serve --play``, ``rwt play``), the
graph has a ``timeline``: nanoseconds since the epoch on the bag's clock. A
Foxglove client then gets ``time`` frames (opcode 0x02) whenever that time
moved (the driver looks every ``TIME_INTERVAL_S``, and before each message
data), and message data log times on the same clock, so its timeline shows
the bag's time; a seek shows as a step. With sim time (``rwt serve
--use-sim-time``) the timeline is the latest ``/clock``: nothing is sent before
the first. Without a timeline (or a time) nothing is sent and log times are the
graph's wall clock.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

from .protocol import encode_time

if TYPE_CHECKING:
    from rwt_graph.port import GraphFront

__all__ = ["TIME_CAPABILITY", "TIME_INTERVAL_S", "ServerTime"]

TIME_CAPABILITY: Final = "time"
TIME_INTERVAL_S: Final = 0.05
"""Seconds between two looks at the timeline while no message comes (20 per second)."""


class ServerTime:
    """One client's server time: the graph's timeline, each new value told once.

    Args:
        graph: the graph whose ``timeline`` is read (it may end: nothing is sent then).
    """

    __slots__ = ("_graph", "_sent")

    def __init__(self, graph: GraphFront) -> None:
        self._graph = graph
        self._sent: int | None = None

    def now(self) -> int | None:
        """The timeline's time in ns, or None when it has none now (no bag, no ``/clock``)."""
        timeline = self._graph.timeline
        return None if timeline is None else timeline()

    def frame(self, now: int) -> bytes | None:
        """The ``time`` frame for ``now``, or None when the client was told it already."""
        if now == self._sent:
            return None
        self._sent = now
        return encode_time(now)
