"""Topics of the in-memory graph (spec 3.3.1-3.3.5, D11, D13).

A topic's type is established by its first advertiser or subscriber; later
participants must agree. A topic lives while it has a publisher or a subscriber.
Each subscriber (one per client) receives every message once; the same
``MessageEvent`` object goes to all of them, so encodings are shared.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from rwt_protocol.errors import GraphError

from .ratelog import EpisodeLog

if TYPE_CHECKING:
    from rwt_protocol.ports import ClientId, MessageCodec, MessageEvent, TopicSink

    from .topic_qos import TopicQos
    from .types import MessageType

__all__ = ["LOSS_REPORT_EVERY_S", "Tap", "Topic"]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

LOSS_REPORT_EVERY_S = 1.0
"""Seconds between two reports of lost messages to a topic's subscribers, at least
(``Topic.report_lost``): the first of an episode goes at once, later ones carry the
count since the last report, so a lossy link costs its subscribers one status a
second at most."""

Tap = Callable[["Topic", "MessageEvent", "ClientId", bool], None]
"""Sees every message published in a graph: ``tap(topic, event, publisher, latched)``.

A tap is no subscriber: it keeps no topic alive and rosapi does not list it. A
link to other processes (``rwt_zenoh``) uses one to forward what is published
here, and skips what it published itself."""


@dataclass(eq=False)
class Topic:
    """One topic: its type, publishers, subscribers and latched message.

    Attributes:
        name: resolved name (``/chatter``).
        msgtype: the established message type.
        publishers: client -> whether it publishes latched (transient local).
        subscribers: client -> the sink receiving its messages; read it freely,
            change it only through ``add_subscriber`` and ``remove_subscriber``
            (``fan_out`` keeps a copy of the sinks it calls).
        latched: the last message of a latched publisher, replayed to each new
            subscriber once (D13).
        latched_by: the publisher of ``latched``; the message goes when it does
            (a transient-local sample lives with its publisher).
        qos: the topic's QoS (protocol 2.1.0, ``topic_qos``), from its first
            registration that gave one; None for a topic nobody gave one. While
            it exists it is the topic's ``fan_out`` (an attribute of the
            instance, so other topics pay nothing), and its excluded subscribers
            are left out of ``sinks`` (D64).
    """

    name: str
    msgtype: MessageType
    publishers: dict[ClientId, bool] = field(default_factory=dict)
    subscribers: dict[ClientId, TopicSink] = field(default_factory=dict)
    latched: MessageEvent | None = None
    latched_by: ClientId | None = None
    # (client, sink) of the subscribers ``fan_out`` calls; None: to be made again
    _calls: tuple[tuple[ClientId, TopicSink], ...] | None = field(default=None, repr=False)
    codec: MessageCodec | None = field(default=None, repr=False, compare=False)
    """``msgtype``'s codec, which the graph gives each event (kept here on first use)."""
    batchable: bool = field(default=False, repr=False, compare=False)
    """Every sink ``fan_out`` calls takes a batch (``BatchSink``), and there is one; known
    once ``sinks`` (or a fan-out) ran since the subscribers last changed (False until then).
    Never for a topic with ``qos``: its messages go one by one through its ``fan_out``."""
    qos: TopicQos | None = field(default=None, repr=False, compare=False)
    _lost: int = field(default=0, repr=False, compare=False)  # lost, not reported yet
    _lost_told: float = field(default=float("-inf"), repr=False, compare=False)

    @property
    def in_use(self) -> bool:
        """Whether anyone still publishes or subscribes."""
        return bool(self.publishers or self.subscribers)

    def add_subscriber(self, client: ClientId, sink: TopicSink) -> bool:
        """Make ``sink`` the subscriber of ``client`` (replacing its earlier one).

        Returns:
            Whether ``client`` was not a subscriber before.
        """
        is_new = client not in self.subscribers
        self.subscribers[client] = sink
        self.changed()
        return is_new

    def remove_subscriber(self, client: ClientId) -> None:
        """Forget ``client`` as a subscriber (nothing if it was none)."""
        if self.subscribers.pop(client, None) is not None:
            self.changed()
        if self.qos is not None:
            self.qos.remove_subscriber(client)

    def remove_publisher(self, client: ClientId) -> None:
        """Forget ``client`` as a publisher, and its latched message (D13)."""
        self.publishers.pop(client, None)
        if self.latched_by == client:
            self.latched = None
            self.latched_by = None
        if self.qos is not None:
            self.qos.remove_publisher(client)

    def changed(self) -> None:
        """The sinks a fan-out calls changed: ``sinks`` makes them again."""
        self._calls = None
        self.batchable = False

    def keep(self, event: MessageEvent, client: ClientId | None) -> None:
        """Keep ``event`` as the latched message, ``client``'s, without delivering it (D13).

        A link hands a relayed sample over this way once its publisher is known
        (``rwt_graph.link.Relays``): the subscribers had it already.
        """
        self.latched = event
        self.latched_by = client

    def report_lost(self, count: int, now: float) -> bool:
        """``count`` messages were lost before they reached this server: tell the subscribers.

        Every subscriber's sink that takes such a report (``rwt_protocol.ports.LossSink``)
        is told at ``now`` (monotonic seconds), at most once per
        ``LOSS_REPORT_EVERY_S``: a report within that time of the last one is kept
        and added to the next (D61). A link calls it on a gap in a remote
        publisher's messages, and with ``count`` 0 later (its sweep), until
        nothing is kept.

        Returns:
            Whether lost messages are kept for a later report.
        """
        self._lost += count
        if not self._lost or now - self._lost_told < LOSS_REPORT_EVERY_S:
            return self._lost > 0
        lost, self._lost, self._lost_told = self._lost, 0, now
        for subscriber, sink in list(self.subscribers.items()):
            on_lost = getattr(sink, "on_lost", None)
            if on_lost is None:
                continue
            try:
                on_lost(lost)
            except Exception:  # a broken subscriber must not hurt the others
                self._failed(subscriber)
        return False

    def check_type(self, msgtype: MessageType) -> None:
        """Refuse a participant that names another type (spec 3.3.1).

        Raises:
            GraphError: ``msgtype`` differs from the established type.
        """
        if msgtype.name != self.msgtype.name:
            raise GraphError(
                f"{self.name} is established with type {self.msgtype.name}, not {msgtype.name}"
            )

    def fan_out(self, event: MessageEvent, latch: bool, client: ClientId | None = None) -> None:
        """Deliver ``event`` to every subscriber; keep it if latched (from ``client``).

        A sink whose ``drops_messages`` attribute is true (a link's remote
        subscription, ``rwt_graph.link.NULL_SINK``: its copy travels on the other
        middleware) is not called: with ``--workers`` each process holds one per
        subscriber of the others, half the calls of a fan-out (benchmarks/README.md,
        "Workers' CPU per delivery"). The sinks called are those subscribed when
        the fan-out starts.
        """
        if latch:
            self.keep(event, client)
        calls = self._calls
        if calls is None:
            calls = self.sinks()
        if self.batchable:  # a batch of one: the call ``on_message`` would make, saved per sink
            self.fan_out_batch([event])
            return
        for subscriber, sink in calls:
            try:
                sink.on_message(event)
            except Exception:  # a broken subscriber must not hurt the others
                self._failed(subscriber)

    def fan_out_batch(self, events: list[MessageEvent]) -> None:
        """Deliver ``events``, in order, to every subscriber, one call per sink.

        Only while ``batchable``: the graph's batched delivery (``GraphCore.flush``),
        and ``fan_out`` of one message, which so makes one call per sink too. Each
        sink's ``on_messages`` gets the whole list. Nothing is latched here.
        """
        calls = self._calls
        if calls is None:
            calls = self.sinks()
        for subscriber, sink in calls:
            try:
                sink.on_messages(events)  # type: ignore[attr-defined]
            except Exception:  # a broken subscriber must not hurt the others
                self._failed(subscriber)

    def sinks(self) -> tuple[tuple[ClientId, TopicSink], ...]:
        """The (client, sink) pairs a fan-out calls; sets ``batchable``."""
        if self._calls is not None:
            return self._calls
        excluded = {} if self.qos is None else self.qos.excluded  # (D64)
        calls = self._calls = tuple(
            (subscriber, sink)
            for subscriber, sink in self.subscribers.items()
            if not getattr(sink, "drops_messages", False) and subscriber not in excluded
        )
        self.batchable = (
            bool(calls)
            and self.qos is None
            and all(callable(getattr(sink, "on_messages", None)) for _, sink in calls)
        )
        return calls

    def _failed(self, subscriber: ClientId) -> None:
        _episodes.log(
            logging.ERROR,
            f"subscriber_failed {self.name}",
            "subscriber %s of %s failed",
            subscriber,
            self.name,
            exc_info=True,
        )
