"""Per-topic counters of the ROS 2 link's inward stages, logged once when the link stops.

A sample from ROS 2 crosses four stages, each counted here per topic so that a
loss can be put on one of them (benchmarks/README.md, "ROS 2 bridge"):

1. taken: the link's take loop wakes with the topic's subscription ready (or
   rclpy's executor calls it back, ``ros2-take-loop`` off: ``wakes``) and the
   link takes what waits in the subscription (``taken``; each wake-up's count
   goes into ``batches``, a histogram by ``BATCH_BOUNDS``). A sample the
   middleware dropped from the subscription's history before it was taken is in
   none of these: it shows as the publisher's count minus ``taken``.
2. handed: queued for the event loop (``handed``) or refused by the handoff's byte
   bound (``refused``, ``handoff.MAX_QUEUED_BYTES``); of those queued, ``expired``
   waited longer than ``handoff.MAX_WAIT_S`` with a newer sample behind them and
   were dropped.
3. published: run on the event loop and published in the graph (``published``),
   or not (``skipped``: the link's own publisher, a foreign definition, a topic no
   longer listened to, a bad sample).
4. per subscriber, the session's queue: the ``event=disconnect`` line of each
   connection says what its outbox queued, dropped (``expired`` of them: past
   their lifespan, ``rwt_ros2.link.LIFESPAN_S``) and sent (``rwt_transports.pump``).

Stage 1 is written by the taking thread only, stages 2-3 under the
handoff's lock or on the event loop: plain integer increments, no lock of their own.
At the link's end one ``event=ros2_counters`` line per topic, at INFO.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import logging

__all__ = ["BATCH_BOUNDS", "LinkCounters", "TopicCounters"]

BATCH_BOUNDS = (1, 2, 4, 16, 64, 256)
"""Lower bounds of the histogram's buckets of samples per wake-up: 1, 2-3,
4-15, 16-63, 64-255, 256 and more (``TAKE_BATCH`` is 256)."""


@dataclass(slots=True)
class TopicCounters:
    """What one topic's samples did at each stage (see the module text); counts of samples."""

    wakes: int = 0
    taken: int = 0
    batches: list[int] = field(default_factory=lambda: [0] * len(BATCH_BOUNDS))
    max_batch: int = 0
    handed: int = 0
    refused: int = 0
    expired: int = 0
    published: int = 0
    skipped: int = 0

    def woke(self, count: int) -> None:
        """One wake-up took ``count`` samples (the taking thread)."""
        self.wakes += 1
        self.taken += count
        self.max_batch = max(self.max_batch, count)
        bucket = 0
        while bucket + 1 < len(BATCH_BOUNDS) and count >= BATCH_BOUNDS[bucket + 1]:
            bucket += 1
        self.batches[bucket] += 1

    def line(self) -> str:
        """The counters as ``key=value`` fields (``batches=1:n,2-3:n,...``)."""
        names = [
            f"{low}" if high - low == 1 else f"{low}-{high - 1}"
            for low, high in zip(BATCH_BOUNDS, (*BATCH_BOUNDS[1:], 0), strict=True)
        ]
        names[-1] = f"{BATCH_BOUNDS[-1]}+"
        batches = ",".join(f"{name}:{n}" for name, n in zip(names, self.batches, strict=True))
        return (
            f"wakes={self.wakes} taken={self.taken} batches={batches} max_batch={self.max_batch} "
            f"handed={self.handed} refused={self.refused} expired={self.expired} "
            f"published={self.published} "
            f"skipped={self.skipped}"
        )


class LinkCounters:
    """``TopicCounters`` by topic name, for the topics the link has subscribed to."""

    def __init__(self) -> None:
        self.topics: dict[str, TopicCounters] = {}

    def of(self, topic: str) -> TopicCounters:
        """The counters of ``topic``, made at its first subscription (event loop)."""
        found = self.topics.get(topic)
        if found is None:
            found = self.topics[topic] = TopicCounters()
        return found

    def log(self, logger: logging.Logger) -> None:
        """One ``event=ros2_counters topic=...`` line per topic that took a sample, at INFO."""
        for topic, counters in sorted(self.topics.items()):
            if counters.wakes:
                logger.info("event=ros2_counters topic=%s %s", topic, counters.line())
