"""Outgoing ``png`` compression off the event loop (docs/limits.md).

Deflating a 200 KB message takes milliseconds; done on the event loop for a
subscriber of a 50 Hz image topic it held every other connection up (a
bystander's p99 near a second). So a message a subscription asked for as
``compression: "png"`` becomes a ``PngPublishJob``, a background job of its
connection: the transport runs it in a worker thread, one at a time per
connection (so the messages keep their order) and hands the frames back
(``Session.finish_job``). Nothing here starts a thread.

What waits is bounded as the outbox is, by bytes and time (D24), never by
count: a client that reads gets every message of a burst, in order, as on
rosbridge_suite. Each waiting message is charged the size of the JSON text it
compresses (``encoding.publish_text_size``) plus ``outbox.FRAME_OVERHEAD_BYTES``,
and the waiting messages count with the outbox: in its fill for input
backpressure (a publisher faster than the deflater is held, within its hold
budget, as by a subscriber that reads slowly), against ``--send-buffer-limit``
(past it the oldest topic messages go, queued or waiting, the slow-consumer
rule) and in the server's memory budget (D44). A subscriber that does not
read is closed after ``--send-timeout`` as any (``backpressure``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..ops.base import Compression
from .encoding import safe_publish_frames

if TYPE_CHECKING:
    from ..ports import MessageEvent
    from .encoding import EncodeFailure, Frames
    from .subscriptions import TopicSubscription

__all__ = ["PngPublishJob", "PngWaiting"]


@dataclass(eq=False, slots=True)
class PngPublishJob:
    """One message to send as a ``png`` op (a background job, ``contract.Job``).

    Attributes:
        subscription: whose message it is (gone when the client unsubscribed).
        event: the message.
        fragment_size: characters of base64 data per ``png`` op, or None.
        cost: bytes it is charged while it waits (module text).
        ready_at: monotonic seconds before which it must not run (at once).
    """

    subscription: TopicSubscription
    event: MessageEvent
    fragment_size: int | None
    cost: int = 0
    ready_at: float = 0.0

    def run(self) -> Frames | EncodeFailure:
        """Deflate and frame the message (in a worker thread): shared by its subscribers."""
        return safe_publish_frames(
            self.event, self.subscription.spelling, Compression.PNG, self.fragment_size
        )


class PngWaiting:
    """The png jobs of one connection not yet taken by its transport, oldest first.

    Attributes:
        bytes: what the waiting jobs are charged, in all (``PngPublishJob.cost``).
    """

    __slots__ = ("_jobs", "bytes")

    def __init__(self) -> None:
        self._jobs: deque[PngPublishJob] = deque()
        self.bytes = 0

    def __len__(self) -> int:
        return len(self._jobs)

    def add(self, job: PngPublishJob) -> None:
        """Note ``job`` as waiting (the newest)."""
        self._jobs.append(job)
        self.bytes += job.cost

    def oldest(self) -> PngPublishJob:
        """Forget the job that waited longest and return it (to be dropped).

        Raises:
            IndexError: none waits.
        """
        job = self._jobs.popleft()
        self.bytes -= job.cost
        return job

    def taken(self, job: PngPublishJob) -> None:
        """The transport took ``job`` (it runs now): it waits no more.

        The transport takes them oldest first, so ``job`` is the oldest.
        """
        jobs = self._jobs
        if jobs and jobs[0] is job:
            jobs.popleft()
            self.bytes -= job.cost

    def clear(self) -> None:
        """Forget every waiting job (the connection closed)."""
        self._jobs.clear()
        self.bytes = 0
