"""A link's topics held back while subscribers they congested catch up, one topic at a time.

A link's samples share one queue (the ROS 2 link's handoff, the Zenoh link's
events), but the subscribers they congest are each one topic's: a reader of
``/cam`` slower than the camera must not hold ``/odom`` back, nor any other
subscriber of it. So a link asks its ``InflowGate`` after each delivery, and
a delivery that congested a subscriber holds its topic alone (``delivered``):
from then on, that topic's samples the link takes from its queue wait here,
in order (``park``), while the hold waits for the congested outboxes to
drain to their low watermark, each within its hold budget (docs/limits.md,
"Backpressure"). When the hold ends, the waiting samples go back to the front
of the link's queue (``resume``), ahead of anything later of that topic.
Every other topic, and every event that is no sample, is delivered at once.
So is a topic in ``never``: an action's feedback, which a hold would keep
back while the goal's result (a reply, never held) passes it and ends the
goal, leaving the feedback behind it nowhere to go.

What waits here is bounded by the link's queue: the samples (or their
tickets) stay counted there until delivered, and they wait no longer than the
congested subscriber's hold budget; past it the subscriber is slow, the topic
goes on, and the subscriber loses its own oldest messages (D24).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Generic, TypeVar

if TYPE_CHECKING:
    from collections.abc import Callable, Coroutine

    from rwt_protocol.ports import ClientId

    from .link import InflowGate, InflowHold

__all__ = ["TopicHolds"]

Item = TypeVar("Item")


class TopicHolds(Generic[Item]):
    """The topics a link holds back, and each one's waiting items (see the module text).

    Used on the event loop only.

    Args:
        start: runs an async function in the link's task group (anyio's
            ``TaskGroup.start_soon``): each hold waits there.
        resume: takes a topic's waiting items back, oldest first, when its hold
            ends: the link puts them at the front of its queue.
        never: topics never held (the link's, kept up to date by it: its
            actions' feedback topics).
    """

    def __init__(
        self,
        start: Callable[[Callable[[], Coroutine[Any, Any, None]]], object],
        resume: Callable[[list[Item]], None],
        never: set[str] | frozenset[str] = frozenset(),
    ) -> None:
        self._start = start
        self._resume = resume
        self._held: dict[str, list[Item]] = {}
        self._never = never

    def __contains__(self, topic: str) -> bool:
        return topic in self._held

    def park(self, topic: str, item: Item) -> bool:
        """Keep ``item`` of ``topic`` back while the topic is held; False: deliver it now."""
        waiting = self._held.get(topic)
        if waiting is None:
            return False
        waiting.append(item)
        return True

    def delivered(
        self, topic: str | None, gate: InflowGate, publisher: ClientId | None = None
    ) -> None:
        """After a delivery of ``topic``: hold the topic if it congested a subscriber.

        ``topic`` None: the delivery was no sample (a reply, a graph event),
        which is never held; what it congested is not waited for. ``publisher``:
        the participant that published the sample, whose hold budget the hold is
        charged to (``InflowGate.take_hold``).
        """
        if not gate.congested():
            return
        hold = gate.take_hold(publisher)
        if hold is None or topic is None or topic in self._held or topic in self._never:
            return
        self._held[topic] = []
        self._start(lambda: self._wait(topic, hold))

    async def _wait(self, topic: str, hold: InflowHold) -> None:
        try:
            await hold.wait()
        finally:
            waiting = self._held.pop(topic)
            if waiting:
                self._resume(waiting)
