"""Local samples on their way to ROS 2: a new publisher's first ones wait until it has matched.

A ROS 2 publisher made a moment ago has not yet matched the subscriptions
already there (the middleware's discovery takes a round trip), and what it
publishes meanwhile reaches none of them. The link makes its publisher of a
topic when a rosbridge client first publishes, so without a wait the first
samples of every advertise-then-publish would be lost. Each topic the link
publishes therefore has a ``Lane``: its samples wait, in order, until the
publisher has matched the subscriptions the link's last sweep saw
(``get_subscription_count``), at most ``MATCH_WAIT_S`` (an incompatible QoS
never matches); then they go, and later ones go at once.

What waits in all lanes together is bounded in bytes (``MAX_OUTFLOW_BYTES``):
past half of it the connection whose publish took it there is held
(``rwt_graph.link.Backlog``: ``Outflow`` is the link's backlog), and past the
bound the lane's oldest sample goes, logged once per topic and episode.
Latched publishers (transient local) do not wait: durability brings their
last sample to a subscriber that matches later. Everything here runs on the
event loop.
"""

from __future__ import annotations

import logging
from collections import deque
from typing import TYPE_CHECKING, Any

import anyio

from rwt_graph.ratelog import EpisodeLog
from rwt_graph.tasks import start_soon
from rwt_protocol.runtime.outbox import water_marks

if TYPE_CHECKING:
    from collections.abc import Callable

    from anyio.abc import TaskGroup

__all__ = ["MATCH_WAIT_S", "MAX_OUTFLOW_BYTES", "SAMPLE_OVERHEAD", "Lane", "Outflow"]

logger = logging.getLogger("rwt.ros2")

MATCH_WAIT_S = 2.0
"""Seconds a new publisher's first samples wait for it to match the subscriptions
already known; past it they go to whatever matched."""

MAX_OUTFLOW_BYTES = 64 * 1024 * 1024
"""Bytes of local samples waiting in all lanes at most (``SAMPLE_OVERHEAD`` each
counted too); watermarks half and a quarter of it."""

SAMPLE_OVERHEAD = 64
"""Bytes counted per waiting sample beyond its CDR, so tiny samples are bounded too."""

_POLL_S = 0.005  # how often a new publisher's match count is read while samples wait


class Outflow:
    """The lanes of one link, and their bytes as a ``rwt_graph.link.Backlog``.

    Args:
        tasks: the link's task group, where lanes wait.
        max_bytes: ``MAX_OUTFLOW_BYTES``.
    """

    def __init__(self, tasks: TaskGroup, max_bytes: int = MAX_OUTFLOW_BYTES) -> None:
        self._tasks = tasks
        self.max_bytes = max_bytes
        self._marks = water_marks(max_bytes)
        self._queued = 0
        self._on_take: Callable[[bool], None] | None = None
        self.drops = EpisodeLog(logger)

    @property
    def queued_bytes(self) -> int:
        """Bytes waiting in all lanes now."""
        return self._queued

    @property
    def water_marks(self) -> tuple[int, int]:
        """(high, low): half and a quarter of ``max_bytes``."""
        return self._marks

    @property
    def congested(self) -> bool:
        """Whether more than the high watermark waits."""
        return self._queued > self._marks[0]

    def watch(self, on_take: Callable[[bool], None] | None) -> None:
        """Call ``on_take(caught_up)`` as waiting samples go out (None: stop)."""
        self._on_take = on_take

    def lane(self, topic: str, handle: Any, *, expected: int) -> Lane:
        """A lane for ``handle``, the rclpy publisher of ``topic``.

        ``expected``: the subscriptions it should match before its first
        sample goes (0: none known, or a latched publisher).
        """
        return Lane(self, topic, handle, expected)

    def _counted(self, delta: int) -> None:
        self._queued += delta
        if delta < 0 and self._on_take is not None:
            self._on_take(self._queued == 0)


class Lane:
    """The samples of one link publisher, in order (see the module text)."""

    def __init__(self, outflow: Outflow, topic: str, handle: Any, expected: int) -> None:
        self._outflow = outflow
        self.topic = topic
        self.handle = handle
        self._expected = expected
        self._held: deque[bytes] = deque()
        self._matched = expected == 0
        self._pumping = False
        self.closed = False

    @property
    def waiting(self) -> int:
        """Samples waiting in the lane."""
        return len(self._held)

    def put(self, data: bytes) -> None:
        """Publish ``data`` now if the publisher has matched, else queue it behind the others."""
        if self.closed:
            return
        if not self._held and self._has_matched():
            self.handle.publish(data)
            return
        outflow = self._outflow
        if self._held and outflow.queued_bytes + len(data) + SAMPLE_OVERHEAD > outflow.max_bytes:
            dropped = self._held.popleft()
            outflow._counted(-(len(dropped) + SAMPLE_OVERHEAD))
            outflow.drops.log(
                logging.WARNING,
                f"outflow:{self.topic}",
                "event=ros2_outflow_dropped topic=%s queued_bytes=%d limit=%d",
                self.topic,
                outflow.queued_bytes,
                outflow.max_bytes,
            )
        self._held.append(data)
        outflow._counted(len(data) + SAMPLE_OVERHEAD)
        if not self._pumping:
            self._pumping = True
            start_soon(outflow._tasks, self._pump)  # maybe from a hand-over's callback

    def take_held(self) -> list[bytes]:
        """Close the lane; what still waits, for the publisher replacing it."""
        self.closed = True
        held = list(self._held)
        self._held.clear()
        if held:
            self._outflow._counted(-sum(len(d) + SAMPLE_OVERHEAD for d in held))
        return held

    def _has_matched(self) -> bool:
        if not self._matched and self.handle.get_subscription_count() >= self._expected:
            self._matched = True
        return self._matched

    async def _pump(self) -> None:
        """Wait until the publisher has matched (``MATCH_WAIT_S`` at most), then publish."""
        try:
            deadline = anyio.current_time() + MATCH_WAIT_S
            while not self.closed and not self._has_matched():
                if anyio.current_time() >= deadline:
                    self._matched = True  # an incompatible subscription never matches
                    break
                await anyio.sleep(_POLL_S)
            while self._held and not self.closed:
                data = self._held.popleft()
                self._outflow._counted(-(len(data) + SAMPLE_OVERHEAD))
                self.handle.publish(data)
        except Exception:  # the publisher was destroyed under the pump: the link goes on
            logger.debug("ros2 outflow of %s stopped", self.topic, exc_info=True)
        finally:
            self._pumping = False
