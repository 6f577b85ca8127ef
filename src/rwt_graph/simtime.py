"""Sim time: the latest ``/clock`` message as the graph's timeline (``use_sim_time``).

``follow_clock`` subscribes to ``/clock`` (``rosgraph_msgs/msg/Clock``, from any
publisher: a ROS 2 node through ``--ros2``, a rosbridge client, Python code) and
makes its latest time the graph's ``timeline`` while it runs, which Foxglove
clients get as server time (docs/foxglove.md, ``rwt serve --use-sim-time``).
Until the first ``/clock`` message the timeline has no time (None). The graph's
clock (rosapi ``get_time``, default header stamps) is not changed.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Final

from .types.convert import time_parts

if TYPE_CHECKING:
    from .graph import Graph

__all__ = ["CLOCK_TOPIC", "SimTime", "follow_clock"]

CLOCK_TOPIC: Final = "/clock"
CLOCK_TYPE: Final = "rosgraph_msgs/Clock"  # either dialect's name resolves
SIM_TIME_NODE: Final = "/rwt_sim_time"
"""The node rosapi lists as ``/clock``'s subscriber."""

_NS: Final = 1_000_000_000


class SimTime:
    """The latest ``/clock`` time; call it for nanoseconds since the epoch, or None before one."""

    __slots__ = ("_ns",)

    def __init__(self) -> None:
        self._ns: int | None = None

    def __call__(self) -> int | None:
        """The latest ``/clock`` time in ns, or None when none came yet."""
        return self._ns

    def receive(self, msg: object) -> None:
        """Take one ``/clock`` message (``{"clock": {"sec": s, "nanosec": ns}}``).

        A message without a usable time (negative, or past what 64 bits of ns
        hold, as Foxglove's ``time`` frame carries) is ignored.
        """
        parts = time_parts(msg.get("clock")) if isinstance(msg, Mapping) else None
        if parts is None:
            return
        ns = parts[0] * _NS + parts[1]
        if 0 <= ns < 2**64:
            self._ns = ns


@contextlib.contextmanager
def follow_clock(graph: Graph) -> Iterator[SimTime]:
    """Make ``/clock`` the graph's timeline inside the ``with`` block.

    Raises:
        GraphError: ``/clock`` already has another type than ``rosgraph_msgs/Clock``.
    """
    sim = SimTime()
    subscription = graph.create_subscription(
        CLOCK_TOPIC, sim.receive, CLOCK_TYPE, node=SIM_TIME_NODE
    )
    try:
        with graph.port.use_timeline(sim):
            yield sim
    finally:
        subscription.close()
