"""One client's subscriptions to one topic: merged parameters, throttle and queue.

Spec 3.3.4 and D11: a client with several subscriptions to a
topic receives one copy of each message; the merged parameters are the lowest
``throttle_rate``, the lowest ``fragment_size``, the highest ``queue_length`` and
the strongest ``compression`` (``cbor-raw`` > ``cbor`` > ``png`` > ``none``).

Throttle and queue follow D12 (REF §5.3 for the reference's behaviour):

- ``throttle_rate`` 0: every message goes out at once (``queue_length`` does not
  matter; the connection's outbox bounds what waits for a slow peer, D24);
- ``throttle_rate`` T ms: leading edge, a message goes out at once when at least
  T has passed since the previous one; otherwise it waits in a queue of
  ``max(1, queue_length)`` messages (at most the server's ``max_queue``, D24)
  that drops its oldest, and the head goes out
  each time a window of T ends, so the latest message of a burst is always
  delivered (the reference loses it);
- changing the parameters keeps the time of the last send and the queue; a
  lower throttle takes effect at once (0 flushes the queue).

A subscription made on a transport's lossy channel (D36) is ``lossy`` while
every id it holds came on that channel: its messages go on the lossy lane,
latest-only. One id from the reliable channel makes the merged subscription
reliable (one copy of each message, D11, on the channel that loses none).

Time is the ``now`` of each message event and of the session's timer; nothing
here reads a clock.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..ops.base import Compression
from ..runtime.backpressure import lost_text
from ..runtime.timers import Timer

if TYPE_CHECKING:
    from collections.abc import Sequence

    from ..ops import Subscribe
    from ..ports import MessageEvent

__all__ = ["BatchTopicSubscription", "MergedParams", "TopicSubscription", "merge"]

_STRENGTH: dict[Compression, int] = {
    Compression.NONE: 0,
    Compression.PNG: 1,
    Compression.CBOR: 2,
    Compression.CBOR_RAW: 3,
}

SubscriptionKey = str | int | None
"""A subscription id as sent, or None for a subscription without id."""

Schedule = Callable[[float, Callable[[float], None]], Timer]
"""Runs a callback with ``now`` at a monotonic deadline (``Session.call_at``)."""


@dataclass(frozen=True, slots=True)
class MergedParams:
    """The effective delivery parameters of one client's topic subscriptions.

    Attributes:
        throttle_rate_ms: minimum interval between messages, milliseconds.
        queue_length: messages buffered while throttled (0 = only the latest).
        fragment_size: largest frame before fragmenting, characters, or None.
        compression: the encoding of delivered messages.
    """

    throttle_rate_ms: int = 0
    queue_length: int = 0
    fragment_size: int | None = None
    compression: Compression = Compression.NONE

    @property
    def throttle_s(self) -> float:
        """``throttle_rate_ms`` in seconds."""
        return self.throttle_rate_ms / 1000.0


def merge(requests: list[Subscribe]) -> MergedParams:
    """Merge the subscribe requests of one client to one topic (D11)."""
    sizes = [r.fragment_size for r in requests if r.fragment_size is not None]
    return MergedParams(
        throttle_rate_ms=min(r.throttle_rate for r in requests),
        queue_length=max(r.queue_length for r in requests),
        fragment_size=min(sizes) if sizes else None,
        compression=max((r.compression for r in requests), key=_STRENGTH.__getitem__),
    )


class TopicSubscription:
    """A client's subscription to one topic: the ids it holds and how to deliver.

    It is the ``TopicSink`` the graph calls.

    Args:
        topic: the resolved topic name.
        spelling: the name as the client wrote it; delivered messages carry it (D26).
        deliver: sends one message to the client now (encoding is the caller's).
        schedule: runs a callback at a monotonic deadline (the session's timers).
        max_queue: the most messages queued whatever ``queue_length`` asks
            (a size the peer controls, D24).
        warn: tells the client a ``warning`` (``on_lost``); None: it is not told.
    """

    def __init__(
        self,
        topic: str,
        spelling: str,
        deliver: Callable[[TopicSubscription, MessageEvent], None],
        schedule: Schedule,
        *,
        max_queue: int = 100,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        self.topic = topic
        self.spelling = spelling
        self.requests: dict[SubscriptionKey, Subscribe] = {}
        self.params = MergedParams()
        self.type_name = ""
        self.queue: deque[MessageEvent] = deque()
        self.last_sent: float | None = None
        self._deliver = deliver
        self._schedule = schedule
        self._max_queue = max(1, max_queue)
        self._timer: Timer | None = None
        self._lossy_ids: set[SubscriptionKey] = set()
        self._warn = warn
        self.lossy = False
        """Every id came on the lossy channel: messages go on the lossy lane (D36)."""

    def add(self, request: Subscribe, now: float, *, lossy: bool = False) -> None:
        """Add or replace the subscription ``request.id`` and re-merge (D11).

        Args:
            request: the subscribe op.
            now: monotonic seconds; a lowered throttle takes effect from here.
            lossy: the op came on the transport's lossy channel (D36).
        """
        self.requests[request.id] = request
        if lossy:
            self._lossy_ids.add(request.id)
        else:
            self._lossy_ids.discard(request.id)
        self.spelling = request.topic
        self._remerge(now)

    def remove(self, key: SubscriptionKey, now: float) -> bool:
        """Remove one subscription id and re-merge; return whether it existed."""
        if key not in self.requests:
            return False
        del self.requests[key]
        self._lossy_ids.discard(key)
        if self.requests:
            self._remerge(now)
        return True

    def close(self) -> None:
        """Stop delivering: cancel the pending window and drop queued messages."""
        self.requests.clear()
        self._lossy_ids.clear()
        self.queue.clear()
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def on_message(self, event: MessageEvent) -> None:
        """Receive one message from the graph (``TopicSink``); throttle and queue it (D12)."""
        now = event.now
        window = self.params.throttle_s
        if not self.queue and self._timer is None and self._open(now, window):
            self._send(event, now)
            return
        self.queue.append(event)
        self._trim()
        self._arm(now)

    def on_lost(self, count: int) -> None:
        """``count`` messages were lost before they reached the server (``LossSink``, D61)."""
        if self._warn is not None:
            self._warn(lost_text(count, self.spelling))

    def _open(self, now: float, window: float) -> bool:
        return window <= 0 or self.last_sent is None or now - self.last_sent >= window

    def _send(self, event: MessageEvent, now: float) -> None:
        self.last_sent = now
        self._deliver(self, event)

    def _trim(self) -> None:
        keep = min(max(1, self.params.queue_length), self._max_queue)
        while len(self.queue) > keep:
            self.queue.popleft()

    def _arm(self, now: float) -> None:
        """Make sure the queue's head goes out when the current window ends."""
        if self._timer is not None or not self.queue:
            return
        if self.params.throttle_s <= 0:
            self._flush(now)
            return
        base = now if self.last_sent is None else self.last_sent
        self._timer = self._schedule(base + self.params.throttle_s, self._window_ended)

    def _window_ended(self, now: float) -> None:
        # The queue is never empty here: a timer is armed only for a queued
        # message, and ``close`` cancels it when it drops the queue.
        self._timer = None
        self._send(self.queue.popleft(), now)
        self._arm(now)

    def _flush(self, now: float) -> None:
        while self.queue:
            self._send(self.queue.popleft(), now)

    def _remerge(self, now: float) -> None:
        self.params = merge(list(self.requests.values()))
        self.lossy = self._lossy_ids.issuperset(self.requests)
        self._trim()
        if self._timer is not None:
            # A changed throttle moves the end of the current window.
            self._timer.cancel()
            self._timer = None
        if self.queue and self._open(now, self.params.throttle_s):
            self._window_ended(now)
        else:
            self._arm(now)


class BatchTopicSubscription(TopicSubscription):
    """A ``TopicSubscription`` that takes a run of messages in one call (a ``BatchSink``).

    Unthrottled with nothing queued, the run goes to ``deliver_many`` whole (the
    session queues each message's frame in the fewest steps); otherwise message by
    message, as ``on_message`` takes them. The ``rosbridge-batch-sink`` shortcut
    (``rwt_protocol.shortcuts``); ``TopicSubscription`` is its general path.

    Args:
        deliver_many: sends a run of messages to the client now, in order.
        *args, **kwargs: as for ``TopicSubscription``.
    """

    def __init__(
        self,
        topic: str,
        spelling: str,
        deliver: Callable[[TopicSubscription, MessageEvent], None],
        deliver_many: Callable[[TopicSubscription, Sequence[MessageEvent]], None],
        schedule: Schedule,
        *,
        max_queue: int = 100,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        super().__init__(topic, spelling, deliver, schedule, max_queue=max_queue, warn=warn)
        self._deliver_many = deliver_many

    def on_messages(self, events: Sequence[MessageEvent]) -> None:
        """Receive a run of one topic's messages (``BatchSink``), as ``on_message`` would each."""
        if self.queue or self._timer is not None or self.params.throttle_s > 0:
            for event in events:
                self.on_message(event)
            return
        if events:
            self.last_sent = events[-1].now
            self._deliver_many(self, events)
