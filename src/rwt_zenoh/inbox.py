"""Remote samples waiting for the event loop, bounded in bytes, dropped per topic oldest first.

Zenoh hands samples over on its own threads as fast as the network brings them;
the event loop decodes and delivers them at its own pace. A peer publishing
faster than that (a hostile one, or a camera on rmw_zenoh) must not grow this
process without bound, so the waiting samples are bounded in bytes (and count),
and past the bound the oldest samples of the topic holding the most go, as a
keep-last depth does: a flood on one topic does not starve the others.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from rwt_graph.ratelog import EpisodeLog

from .limits import MAX_QUEUED_BYTES, MAX_QUEUED_SAMPLES, SAMPLE_OVERHEAD

if TYPE_CHECKING:
    from collections.abc import Callable, Sized

__all__ = ["Inbox", "Sample"]

logger = logging.getLogger("rwt.zenoh")


@dataclass(frozen=True)
class Sample:
    """One remote sample: its CDR payload, rmw_zenoh attachment and its handler.

    ``deliver(payload, attachment)`` runs on the event loop when it is taken.
    ``payload`` is the CDR ``bytes``, or what stands for them and has their
    length: a large remote sample's ``zenoh.ZBytes``, the outbox's
    ``deferred.Deferred`` (see ``deferred``).
    """

    deliver: Callable[[Any, bytes | None], None]
    payload: Sized
    attachment: bytes | None

    @property
    def size(self) -> int:
        """What it costs to hold, bytes."""
        return len(self.payload) + len(self.attachment or b"") + SAMPLE_OVERHEAD


@dataclass
class _Queue:
    samples: deque[Sample] = field(default_factory=deque)
    bytes: int = 0
    tickets: int = 0  # takes announced to the event loop and not yet made


class Inbox:
    """Per-topic queues of remote samples, bounded together (thread-safe).

    ``put`` runs on Zenoh's threads, ``take`` on the event loop. Every sample put
    is announced by at most one ticket; ``take`` redeems one, so a dropped sample
    leaves no work behind (a ticket without a sample takes nothing).

    Args:
        max_bytes: bytes held at most (payload, attachment and ``SAMPLE_OVERHEAD``
            per sample); ``limits.MAX_QUEUED_BYTES`` by default.
        max_samples: samples held at most, however small.
        drop_log: where drops are logged, once per episode and topic.
    """

    def __init__(
        self,
        max_bytes: int = MAX_QUEUED_BYTES,
        max_samples: int = MAX_QUEUED_SAMPLES,
        *,
        drop_log: EpisodeLog | None = None,
    ) -> None:
        self.max_bytes = max_bytes
        self.max_samples = max_samples
        self._queues: dict[str, _Queue] = {}
        self._bytes = 0
        self._count = 0
        self._lock = threading.Lock()
        self._room = threading.Condition(self._lock)  # notified by take and close
        self._closed = False
        self._log = drop_log or EpisodeLog(logger)
        self.dropped = 0

    @property
    def bytes(self) -> int:
        """Bytes held now."""
        return self._bytes

    def put(self, topic: str, sample: Sample, *, wait_s: float = 0.0) -> bool:
        """Hold ``sample`` of ``topic``, dropping the oldest samples it displaces.

        Args:
            topic: the queue's name (a topic, or a Zenoh key).
            sample: what to hold.
            wait_s: seconds to wait for room before dropping (0: never wait). Only a
                Zenoh thread may wait (a reliable sample: its wait holds the
                peer back over TCP), never the event loop.

        Returns:
            Whether the event loop needs a new ticket for ``topic`` (one ``take``).
        """
        size = sample.size
        with self._lock:
            if size > self.max_bytes:
                self._dropped(topic, "larger than the queue")
                return False
            if wait_s > 0:
                self._room.wait_for(lambda: self._closed or self._fits(size), wait_s)
            queue = self._queues.get(topic)
            if queue is None:
                queue = self._queues[topic] = _Queue()
            while not self._fits(size):
                self._drop_oldest(self._victim(topic, queue))
            queue.samples.append(sample)
            queue.bytes += size
            self._bytes += size
            self._count += 1
            if queue.tickets >= len(queue.samples):
                return False
            queue.tickets += 1
            return True

    def close(self) -> None:
        """Stop every wait for room: what comes after is dropped as when full."""
        with self._lock:
            self._closed = True
            self._room.notify_all()

    def _fits(self, size: int) -> bool:
        return self._bytes + size <= self.max_bytes and self._count < self.max_samples

    def take(self, topic: str) -> Sample | None:
        """Redeem one ticket of ``topic``: its oldest sample, None if dropped meanwhile."""
        with self._lock:
            queue = self._queues.get(topic)
            if queue is None:
                return None
            queue.tickets -= 1
            sample = queue.samples.popleft() if queue.samples else None
            if sample is not None:
                queue.bytes -= sample.size
                self._bytes -= sample.size
                self._count -= 1
                self._room.notify_all()
            if queue.tickets <= 0 and not queue.samples:
                del self._queues[topic]
            return sample

    def _victim(self, topic: str, queue: _Queue) -> str:
        """The topic to drop from: ``topic`` if it holds its share, else the largest."""
        if queue.samples and queue.bytes * len(self._queues) >= self._bytes:
            return topic
        return max(self._queues, key=lambda name: self._queues[name].bytes)

    def _drop_oldest(self, topic: str) -> None:
        queue = self._queues[topic]
        sample = queue.samples.popleft()
        queue.bytes -= sample.size
        self._bytes -= sample.size
        self._count -= 1
        self._dropped(topic, "the queue is full: the oldest goes, as with a keep-last depth")

    def _dropped(self, topic: str, reason: str) -> None:
        self.dropped += 1
        self._log.log(
            logging.WARNING,
            f"zenoh_samples_dropped:{topic}",
            "event=zenoh_samples_dropped topic=%s limit_bytes=%d reason=%r",
            topic,
            self.max_bytes,
            reason,
        )
