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

Its QoS (protocol 2.1.0's ``qos``, ``subscription_qos``): the history bounds the
throttle queue as the queue of frames (D63), the lifespan and reliability go with
each message to the outbox (``rule``, ``lifespan_s``), and a deadline the topic
misses warns the client once per episode, checked at most every
``DEADLINE_CHECK_S`` (D65).

A subscription made on a transport's lossy channel (D36) is ``lossy`` while
every id it holds came on that channel: its messages go on the lossy lane,
latest-only. One id from the reliable channel makes the merged subscription
reliable (one copy of each message, D11, on the channel that loses none).

Time is the ``now`` of each message event and of the session's timer; nothing
here reads a clock.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..ops.base import Compression
from ..runtime.backpressure import lost_text
from .deadline import DEADLINE_CHECK_S, DeadlineWatch, Schedule
from .subscription_qos import SubscriptionQos

if TYPE_CHECKING:
    from collections.abc import Sequence

    from ..ops import Subscribe
    from ..ports import MessageEvent
    from ..qos import QosProfile
    from ..runtime.timers import Timer

__all__ = [
    "DEADLINE_CHECK_S",
    "BatchTopicSubscription",
    "MergedParams",
    "TopicSubscription",
    "merge",
]

_STRENGTH: dict[Compression, int] = {
    Compression.NONE: 0,
    Compression.PNG: 1,
    Compression.CBOR: 2,
    Compression.CBOR_RAW: 3,
}

SubscriptionKey = str | int | None
"""A subscription id as sent, or None for a subscription without id."""

Warn = Callable[["TopicSubscription", str], None]
"""Tells the client of a subscription's QoS event (a warning status)."""


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
        deliver_ruled: sends one message of a subscription with QoS (``rule``);
            None: ``deliver`` sends those too.
        schedule: runs a callback at a monotonic deadline (the session's timers).
        max_queue: the most messages queued whatever ``queue_length`` asks
            (a size the peer controls, D24).
        warn: tells the client a ``warning`` (``on_lost``); None: it is not told.
        qos_warn: tells the client of a QoS event (left out of the topic, a missed
            deadline); None: nobody is told.
        default_lifespan_s: the server's lifespan for subscriptions giving none
            (``--qos-lifespan``, D63; inf: none).
        reads_qos: whether the ops' ``qos`` is honoured (not with ``--compat
            rosbridge-2.1``, ``compat.Compat.reads_qos``).

    Attributes:
        rule, lifespan_s: what its messages take to the outbox (``subscription_qos``;
            ``rule`` None: no QoS at all, the plain path).
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
        qos_warn: Warn | None = None,
        default_lifespan_s: float = math.inf,
        reads_qos: bool = True,
        deliver_ruled: Callable[[TopicSubscription, MessageEvent], None] | None = None,
    ) -> None:
        self.topic = topic
        self.spelling = spelling
        self.requests: dict[SubscriptionKey, Subscribe] = {}
        self.params = MergedParams()
        self.type_name = ""
        self.queue: deque[MessageEvent] = deque()
        self.last_sent: float | None = None
        self._deliver = self._plain = deliver
        self._ruled = deliver_ruled or deliver
        self._each_set = False  # ``BatchTopicSubscription``'s own ``on_messages`` is set
        self._schedule = schedule
        self._max_queue = max(1, max_queue)
        self._timer: Timer | None = None
        self._lossy_ids: set[SubscriptionKey] = set()
        self._warn = warn
        self.lossy = False
        """Every id came on the lossy channel: messages go on the lossy lane (D36)."""
        self._qos_warn = qos_warn
        self._reads_qos = reads_qos
        self.qos = SubscriptionQos(default_lifespan_s)
        self.rule = self.qos.rule
        self.lifespan_s = self.qos.lifespan_s
        self._latest: Callable[[], float] | None = None  # the topic's latest message time
        self._since = 0.0  # when its deadline started counting (monotonic seconds)
        self._deadline = DeadlineWatch(schedule, self._deadline_missed)
        self._qos_changed()  # the server's default lifespan may give it a rule already

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
        if not self._since:
            self._since = now
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

    @property
    def requested_qos(self) -> QosProfile | None:
        """The merged ``qos`` of its ids (D11, D63), or None when none gave one."""
        return self.qos.requested

    def close(self) -> None:
        """Stop delivering: cancel the pending window and drop queued messages."""
        self.requests.clear()
        self._lossy_ids.clear()
        self.queue.clear()
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._deadline.cancel()
        self._latest = None

    def on_qos_offered(
        self, offered: QosProfile | None, reasons: list[str], latest: Callable[[], float]
    ) -> None:
        """The topic's QoS offer, why this subscription is left out of it, its latest message.

        The graph calls it (``rwt_graph.topic_qos``) when the subscription starts
        and whenever the offer changes; a subscription left out tells its client
        why (D64), and its deadline follows the offer's when it gives none (D65).
        """
        if not self.requests:
            return  # closed meanwhile
        left_out = self.qos.offer(offered, reasons) and reasons
        self._latest = latest
        self._qos_changed()
        if left_out and self._qos_warn is not None:
            self._qos_warn(self, self.qos.excluded_text(self.spelling))

    def _qos_changed(self) -> None:
        self.rule = self.qos.rule
        self.lifespan_s = self.qos.lifespan_s
        # the QoS path only for a subscription with QoS: the plain one checks nothing
        self._deliver = self._plain if self.rule is None else self._ruled
        self._trim()
        self._watch_deadline()

    def _watch_deadline(self) -> None:
        """(Re)arm the deadline's check for the current deadline and latest message (D65)."""
        if self._latest is None or not self.requests:
            self._deadline.cancel()
        else:
            self._deadline.arm(self.qos.deadline_s, self._latest, self._since)

    def _deadline_missed(self) -> None:
        """The topic missed the deadline: warn the client, once per episode (D65)."""
        if self._qos_warn is not None and self.requests:
            self._qos_warn(self, self.qos.deadline_text(self.spelling))

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
        rule = self.rule
        if rule is not None and rule.depth:
            keep = min(keep, rule.depth)  # the history's depth bounds this queue too (D63)
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
        asked = (
            None if r.qos is None or not self._reads_qos else r.qos.profile()
            for r in self.requests.values()
        )
        if self.qos.request(asked):
            self._qos_changed()
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
        qos_warn: Warn | None = None,
        default_lifespan_s: float = math.inf,
        reads_qos: bool = True,
        deliver_ruled: Callable[[TopicSubscription, MessageEvent], None] | None = None,
    ) -> None:
        super().__init__(
            topic,
            spelling,
            deliver,
            schedule,
            max_queue=max_queue,
            warn=warn,
            qos_warn=qos_warn,
            default_lifespan_s=default_lifespan_s,
            reads_qos=reads_qos,
            deliver_ruled=deliver_ruled,
        )
        self._deliver_many = deliver_many

    def _each(self, events: Sequence[MessageEvent]) -> None:
        """``on_messages`` of a subscription with QoS: ``on_message`` of each."""
        for event in events:
            self.on_message(event)

    def on_messages(self, events: Sequence[MessageEvent]) -> None:
        """Receive a run of one topic's messages (``BatchSink``), as ``on_message`` would each."""
        if self.queue or self._timer is not None or self.params.throttle_s > 0:
            for event in events:
                self.on_message(event)
            return
        if events:
            self.last_sent = events[-1].now
            self._deliver_many(self, events)

    def _qos_changed(self) -> None:
        super()._qos_changed()
        # a run goes message by message with QoS (each its own end of lifespan, D63):
        # the instance's own ``on_messages`` then, so the plain one checks nothing.
        # (Set and deleted as attributes: ``vars(self)`` would make the instance's
        # dict a real one, and every attribute read of the hot path slower.)
        each = self.rule is not None
        if each != self._each_set:
            self._each_set = each
            if each:
                object.__setattr__(self, "on_messages", self._each)
            else:
                object.__delattr__(self, "on_messages")
