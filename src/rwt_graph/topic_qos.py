"""The QoS of one topic (protocol 2.1.0's ``qos``; D62-D65 of docs/decisions.md).

A topic gets a ``TopicQos`` at its first registration that carries a ``qos``
(a publisher's or a subscriber's); a topic nobody gave one keeps none, and its
delivery is what it always was (D13's latching, no per-message work here).

- **One offer per topic** (D62). The graph has one publisher per topic, as the
  reference's node has one rclpy publisher: the first publisher registration with
  a ``qos`` fixes the topic's offered QoS for every message published on it, and
  it stands while a publisher that registered with a ``qos`` remains. A later one
  shares it; the session tells its client when its own differed. Publishers that
  gave no ``qos`` neither fix nor end it.
- **Transient local** (D63). With a transient-local offer, the topic keeps its
  last ``keep`` messages (``qos.MAX_DEPTH`` at most, and ``max_store_bytes`` of
  them, and all topics' stores together at most their ``StoreBudget``, each
  keeping its newest message as a latched topic does), dropping the oldest, and a
  new subscriber that asks for transient local (or asks nothing: the adaptive
  default) gets those not past their lifespan, in
  order, before anything newer: the last ``min(offer's, its own)`` of them. The
  kept messages go when the offer does, as a transient-local sample lives with
  its writer.
- **Lifespan** (D63). With a lifespan in the offer, each message published on the
  topic expires that long after it was published (``MessageEvent.expires``):
  never replayed, and never taken from a subscriber's queue after it
  (``rwt_protocol.runtime.outbox``).
- **Incompatible subscribers** (D64). A subscriber whose request cannot match
  the offer by ROS 2's rules (``qos.incompatibilities``) is left out of the
  topic's delivery while the offer stands, as ROS 2 leaves such a pair
  unmatched; its sink is told why (``on_qos_offered``), and the session warns
  its client. Its subscription stays, and resumes when the offer goes.
- **Publishers told** (D64, D65). A publisher registration with a ``qos`` may
  give a watch (``OfferWatch``): it is told the offer (and the time of the
  topic's latest message, for the offer's deadline) at registration, whenever
  it changes, and None once its client no longer publishes with one; and, once
  per episode, that a subscription asks what the offer cannot meet (ROS 2's
  "offered incompatible QoS"): from the first subscriber left out until none
  is, or the offer changes.
- **Sinks** that have ``on_qos_offered(offered, reasons, latest)`` are told the
  topic's offer when they subscribe and whenever it changes, with the reasons
  they are left out (empty when they are not) and a function giving the
  monotonic time of the topic's latest message (``-inf`` before any): a rosbridge
  subscription resolves its ``best_available`` policies and checks its deadline
  with them (D65).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rwt_protocol.qos import QosProfile, incompatibilities

from .ratelog import EpisodeLog

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId, MessageEvent, OfferWatch, TopicSink

    from .topics import Topic

__all__ = ["STORES_MAX_BYTES", "STORE_MAX_BYTES", "StoreBudget", "TopicQos", "event_bytes"]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)

STORE_MAX_BYTES = 16 * 1024 * 1024
"""Bytes of messages one topic's transient-local store keeps at most (D63): the default
``--send-buffer-limit``, so a late subscriber's replay fits its queue. The server sets
it from its own limit (``GraphCore.max_store_bytes``); past it the oldest go."""


STORES_MAX_BYTES = 256 * 1024 * 1024
"""Bytes all topics' transient-local stores keep together at most (D63), without a server;
a server sets its ``--memory-budget``. Past it, the store being added to drops its
oldest messages, down to its newest one (what D13 keeps of a latched topic)."""


@dataclass
class StoreBudget:
    """The bytes all of a graph's transient-local stores hold, and their bound (D63).

    Attributes:
        limit: the most bytes the stores keep together.
        used: the bytes they keep now.
    """

    limit: int = STORES_MAX_BYTES
    used: int = 0


def event_bytes(event: MessageEvent) -> int:
    """What a message costs a store, bytes: its wire form, made once and shared.

    The serialized form (CDR, ROS 1's) is the one a link or a Foxglove client
    sends, so it is kept on the event (``MessageEvent.memo``) for them too.
    """
    wire = event.wire
    if wire is not None:
        return len(wire)
    codec = event.codec
    if codec is None:
        return 0
    try:
        return len(event.memo("qos-size", lambda: codec.serialize(event.msg)))
    except Exception:  # a message its codec cannot write is delivered, and reported, elsewhere
        return 0


class TopicQos:
    """The QoS state of one topic (the module text).

    Args:
        topic: the topic.
        clock: the graph's monotonic clock (seconds).
        max_store_bytes: the store's byte bound.
        budget: the bound of all the graph's stores together (shared).

    Attributes:
        offered: the offer, resolved for a publisher (``for_publisher``), or None.
        asked: each publisher that registered with a ``qos``: what it asked.
        requested: each subscriber that subscribed with a ``qos``: what it asked.
        excluded: subscribers left out of the delivery (D64), with their reasons.
        watches: the publishers' watches (``OfferWatch``), by client.
        store: the kept messages, oldest first (transient local, D63).
    """

    def __init__(
        self,
        topic: Topic,
        clock: Callable[[], float],
        max_store_bytes: int,
        budget: StoreBudget | None = None,
    ) -> None:
        self.topic = topic
        self._clock = clock
        self.max_store_bytes = max_store_bytes
        self.budget = budget or StoreBudget()
        self.offered: QosProfile | None = None
        self.asked: dict[ClientId, QosProfile] = {}
        self.requested: dict[ClientId, QosProfile] = {}
        self.excluded: dict[ClientId, list[str]] = {}
        self.watches: dict[ClientId, OfferWatch] = {}
        self._told_incompatible: set[ClientId] = set()  # publishers told this episode (D64)
        self.store: deque[MessageEvent] = deque()
        self._store_sizes: deque[int] = deque()
        self.store_bytes = 0
        self.last_message = -math.inf  # monotonic seconds of the latest message (D65)

    @property
    def idle(self) -> bool:
        """Whether nothing here is in force any more (no offer, no request)."""
        return self.offered is None and not self.requested

    # ---- registrations -------------------------------------------------------------

    def add_publisher(
        self, client: ClientId, qos: QosProfile, watch: OfferWatch | None = None
    ) -> None:
        """``client`` publishes with ``qos``: the first such fixes the offer (D62).

        ``watch`` is told the offer now and as it goes (module text).
        """
        self.asked[client] = qos
        if watch is not None:
            replaced = self.watches.get(client)
            if replaced is not None and replaced is not watch:
                self._call_watch(replaced.on_offer, None, self.latest)  # the latest one's turn
            self.watches[client] = watch
            self._told_incompatible.discard(client)  # a new registration: told anew
        if self.offered is None:
            self._offer(qos.for_publisher())
        elif watch is not None:
            self._tell_watch(client, watch)

    def remove_publisher(self, client: ClientId) -> None:
        """``client`` no longer publishes: the offer ends with the last that asked one."""
        watch = self.watches.pop(client, None)
        self._told_incompatible.discard(client)
        if watch is not None:
            self._call_watch(watch.on_offer, None, self.latest)
        if self.asked.pop(client, None) is not None and not self.asked:
            self._offer(None)

    def add_subscriber(self, client: ClientId, qos: QosProfile | None, sink: TopicSink) -> None:
        """``client`` subscribes asking ``qos`` (None: the adaptive default); tell its sink."""
        if qos is None:
            self.requested.pop(client, None)
        else:
            self.requested[client] = qos
        reasons = self._judge(client)
        self._tell(sink, reasons)

    def remove_subscriber(self, client: ClientId) -> None:
        """``client`` no longer subscribes."""
        self.requested.pop(client, None)
        if self.excluded.pop(client, None) is not None:
            self.topic.changed()
            if not self.excluded:
                self._told_incompatible.clear()  # the episode ends (D64)

    def resolved(self, client: ClientId) -> QosProfile | None:
        """What subscriber ``client`` asked, resolved against the offer; None: nothing asked."""
        asked = self.requested.get(client)
        return None if asked is None else asked.for_subscription(self.offered)

    def _judge(self, client: ClientId) -> list[str]:
        """Whether ``client`` is left out of the delivery now (D64); its reasons."""
        offered, asked = self.offered, self.resolved(client)
        reasons = [] if offered is None or asked is None else incompatibilities(offered, asked)
        before = self.excluded.get(client)
        if reasons:
            self.excluded[client] = reasons
        else:
            self.excluded.pop(client, None)
            if not self.excluded:
                self._told_incompatible.clear()  # the episode ends (D64)
        if bool(before) != bool(reasons):
            self.topic.changed()
        if reasons and offered is not None:
            for publisher, watch in list(self.watches.items()):
                if publisher not in self._told_incompatible:
                    self._told_incompatible.add(publisher)
                    self._call_watch(watch.on_incompatible, offered, reasons)
        return reasons

    def _offer(self, offered: QosProfile | None) -> None:
        """Make ``offered`` the topic's offer; tell the watches; judge and tell every subscriber."""
        self.offered = offered
        self._told_incompatible.clear()  # a new offer, a new episode (D64)
        if offered is None or not offered.transient_local:
            self.budget.used -= self.store_bytes
            self.store.clear()
            self._store_sizes.clear()
            self.store_bytes = 0
        for watch in list(self.watches.values()):
            self._call_watch(watch.on_offer, offered, self.latest)
        for client, sink in list(self.topic.subscribers.items()):
            self._tell(sink, self._judge(client))

    def _tell_watch(self, client: ClientId, watch: OfferWatch) -> None:
        """Tell a publisher's watch the offer; and of a subscriber left out, if any is (D64)."""
        self._call_watch(watch.on_offer, self.offered, self.latest)
        offered = self.offered
        if offered is not None and self.excluded and client not in self._told_incompatible:
            self._told_incompatible.add(client)
            self._call_watch(watch.on_incompatible, offered, next(iter(self.excluded.values())))

    def _call_watch(self, call: Callable[..., None], *args: object) -> None:
        try:
            call(*args)
        except Exception:  # a broken publisher must not hurt the others
            _episodes.log(
                logging.ERROR,
                f"qos_watch_failed {self.topic.name}",
                "a publisher of %s failed to take its QoS",
                self.topic.name,
                exc_info=True,
            )

    def _tell(self, sink: TopicSink, reasons: list[str]) -> None:
        told = getattr(sink, "on_qos_offered", None)
        if told is None:
            return
        try:
            told(self.offered, reasons, self.latest)
        except Exception:  # a broken subscriber must not hurt the others
            _episodes.log(
                logging.ERROR,
                f"qos_sink_failed {self.topic.name}",
                "a subscriber of %s failed to take its QoS",
                self.topic.name,
                exc_info=True,
            )

    # ---- messages ------------------------------------------------------------------

    def latest(self) -> float:
        """The monotonic time of the topic's latest message, ``-inf`` before any (D65)."""
        return self.last_message

    def fan_out(self, event: MessageEvent, latch: bool, client: ClientId | None = None) -> None:
        """``Topic.fan_out`` with the offer applied: lifespan, the store (D63), exclusions (D64).

        Installed as the topic's ``fan_out`` while this state exists, so a topic
        without QoS pays nothing for it.
        """
        self.last_message = event.now
        offered = self.offered
        if offered is not None:
            if not math.isinf(offered.lifespan_s):
                event = event.expiring(event.now + offered.lifespan_s)
            if offered.transient_local:
                self._keep(event, offered.keep)
        type(self.topic).fan_out(self.topic, event, latch, client)

    def _keep(self, event: MessageEvent, keep: int) -> None:
        """Keep ``event`` in the store, dropping the oldest past ``keep`` or the byte bound."""
        size = event_bytes(event)
        budget = self.budget
        self.store.append(event)
        self._store_sizes.append(size)
        self.store_bytes += size
        budget.used += size
        while len(self.store) > keep or (
            len(self.store) > 1
            and (self.store_bytes > self.max_store_bytes or budget.used > budget.limit)
        ):
            self._drop_oldest()

    def _drop_oldest(self) -> None:
        self.store.popleft()
        size = self._store_sizes.popleft()
        self.store_bytes -= size
        self.budget.used -= size

    def replay(self, client: ClientId, sink: TopicSink) -> bool:
        """Give a new subscriber what the store keeps for it (D63), oldest first.

        Returns:
            Whether it may have D13's latched message too: it did not ask for
            volatile and is not left out.
        """
        if client in self.excluded:
            return False
        asked = self.resolved(client)
        if asked is not None and not asked.transient_local:
            return False  # volatile: no history, as ROS 2
        if not self.store:
            return True
        now = self._clock()
        while self.store and self.store[0].expires <= now:  # past its lifespan: never replayed
            self._drop_oldest()
        keep = len(self.store) if asked is None else min(len(self.store), asked.keep)
        for event in list(self.store)[len(self.store) - keep :]:
            sink.on_message(event)
        return True
