"""Outgoing ``png`` compression off the event loop (docs/limits.md).

Deflating a 200 KB message takes milliseconds; done on the event loop for a
subscriber of a 50 Hz image topic it held every other connection up (a
bystander's p99 near a second). So a message a subscription asked for as
``compression: "png"`` becomes a ``PngPublishJob``, a background job of its
connection: the transport runs it in a worker thread, one at a time per
connection (so each subscription's messages keep their order) and hands the
frames back (``Session.finish_job``). What waits is bounded: at most
``MAX_PNG_WAITING`` messages a topic, the oldest dropped first (a subscriber's
``queue_length`` rule, D24), so a publisher faster than the deflater costs the
subscriber its oldest messages, never memory. Nothing here starts a thread.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from ..ops.base import Compression
from .encoding import safe_publish_frames

if TYPE_CHECKING:
    from ..ports import MessageEvent
    from .encoding import EncodeFailure, Frames
    from .subscriptions import TopicSubscription

__all__ = ["MAX_PNG_WAITING", "PngPublishJob", "PngWaiting"]

MAX_PNG_WAITING: Final = 4
"""Messages of one topic waiting to be deflated for one connection; more drop the oldest."""


@dataclass(eq=False, slots=True)
class PngPublishJob:
    """One message to send as a ``png`` op (a background job, ``contract.Job``).

    Attributes:
        subscription: whose message it is (gone when the client unsubscribed).
        event: the message.
        fragment_size: characters of base64 data per ``png`` op, or None.
        ready_at: monotonic seconds before which it must not run (at once).
    """

    subscription: TopicSubscription
    event: MessageEvent
    fragment_size: int | None
    ready_at: float = 0.0

    def run(self) -> Frames | EncodeFailure:
        """Deflate and frame the message (in a worker thread): shared by its subscribers."""
        return safe_publish_frames(
            self.event, self.subscription.spelling, Compression.PNG, self.fragment_size
        )


class PngWaiting:
    """The png jobs of one connection not yet taken by its transport, by topic."""

    __slots__ = ("_by_topic",)

    def __init__(self) -> None:
        self._by_topic: dict[str, deque[PngPublishJob]] = {}

    def add(self, job: PngPublishJob) -> PngPublishJob | None:
        """Note ``job`` as waiting; the oldest of its topic to drop when over the bound."""
        waiting = self._by_topic.setdefault(job.subscription.topic, deque())
        waiting.append(job)
        return waiting.popleft() if len(waiting) > MAX_PNG_WAITING else None

    def taken(self, job: PngPublishJob) -> None:
        """The transport took ``job`` (it runs now): it waits no more."""
        waiting = self._by_topic.get(job.subscription.topic)
        if waiting and waiting[0] is job:
            waiting.popleft()
            if not waiting:
                del self._by_topic[job.subscription.topic]

    def clear(self) -> None:
        """Forget every waiting job (the connection closed)."""
        self._by_topic.clear()
