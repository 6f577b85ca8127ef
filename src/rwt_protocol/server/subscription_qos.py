"""The QoS of one client's subscription to a topic (protocol 2.1.0; D63-D65).

What a client's ``subscribe`` ops ask (their ``qos``, merged per D11: one copy of
each message serves every id, so the merge is what the most demanding id needs
and what the most permissive accepts), what the topic offers (the graph tells it,
``rwt_graph.topic_qos``), and what follows for the messages it sends:

- ``rule`` (``runtime.outbox.QueueRule``): at most ``keep`` messages of the topic
  wait for the client (its history, D63), and a best-effort subscription's are
  dropped first under pressure (D64); None when neither the subscription nor
  its topic has QoS and the server sets no default lifespan: the message then
  takes the path it always took, at no added cost.
- ``lifespan_s``: no message older than this is sent (D63); the subscription's
  own, else the server's default (``--qos-lifespan``), else none. A message
  whose topic offers a lifespan (``MessageEvent.expires``) keeps that bound too.
- ``deadline_s``: the longest the subscription waits between messages before
  its client is warned, once per episode (D65): its own deadline, else the
  one its topic offers.

Nothing here reads a clock.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..qos import Durability, History, QosProfile, Reliability, format_seconds
from ..runtime.outbox import QueueRule

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["SubscriptionQos", "merge_qos"]

_RELIABILITY_ORDER = (Reliability.RELIABLE, Reliability.BEST_AVAILABLE, Reliability.BEST_EFFORT)
_DURABILITY_ORDER = (Durability.TRANSIENT_LOCAL, Durability.BEST_AVAILABLE, Durability.VOLATILE)


def merge_qos(requests: Iterable[QosProfile | None]) -> QosProfile | None:
    """The QoS one copy of each message must meet for every id (D11, D63).

    An id without ``qos`` asks nothing: it takes every message, however old
    (no lifespan, the whole history). The most demanding of reliability and
    durability, the shortest deadline; the deepest history and the longest
    lifespan, so no id misses a message it would have had alone.

    Returns:
        The merged profile, or None when no id gave a ``qos``.
    """
    given = list(requests)
    profiles = [profile for profile in given if profile is not None]
    if not profiles:
        return None
    plain = len(profiles) < len(given)  # an id asked nothing: it takes everything
    keep_all = plain or any(p.history is History.KEEP_ALL for p in profiles)
    return QosProfile(
        history=History.KEEP_ALL if keep_all else History.KEEP_LAST,
        depth=max(p.depth for p in profiles),
        reliability=min((p.reliability for p in profiles), key=_RELIABILITY_ORDER.index),
        durability=min((p.durability for p in profiles), key=_DURABILITY_ORDER.index),
        deadline_s=min(p.deadline_s for p in profiles),
        deadline_best_available=all(p.deadline_best_available for p in profiles),
        lifespan_s=math.inf if plain else max(p.lifespan_s for p in profiles),
    )


class SubscriptionQos:
    """What one subscription asks, what its topic offers, and the rules that follow (module text).

    Args:
        default_lifespan_s: the server's lifespan for subscriptions that give none
            (``--qos-lifespan``; inf: none).

    Attributes:
        requested: the merged request of the subscription's ids, or None.
        offered: the topic's offer, or None.
        reasons: why the subscription is left out of the topic's delivery (D64).
        effective: ``requested`` resolved against ``offered`` (``best_available``).
        rule: the queue rule of its messages, or None (module text).
        lifespan_s: the lifespan its messages get in its queue, seconds.
        deadline_s: its deadline, seconds (inf: none).
    """

    def __init__(self, default_lifespan_s: float = math.inf) -> None:
        self.default_lifespan_s = default_lifespan_s
        self.requested: QosProfile | None = None
        self.offered: QosProfile | None = None
        self.told = False  # the graph told an offer (the topic has QoS)
        self.reasons: list[str] = []
        self.effective: QosProfile | None = None
        self.rule: QueueRule | None = None
        self.lifespan_s = default_lifespan_s
        self.deadline_s = math.inf
        self._update()

    def request(self, requests: Iterable[QosProfile | None]) -> bool:
        """Merge the ids' requests; return whether the merged request changed."""
        merged = merge_qos(requests)
        if merged == self.requested:
            return False
        self.requested = merged
        self._update()
        return True

    def offer(self, offered: QosProfile | None, reasons: list[str]) -> bool:
        """The topic's offer, and why it leaves this one out; whether those reasons changed."""
        changed = reasons != self.reasons
        self.offered, self.reasons, self.told = offered, reasons, True
        self._update()
        return changed

    def _update(self) -> None:
        requested = self.requested
        effective = None if requested is None else requested.for_subscription(self.offered)
        self.effective = effective
        lifespan = self.default_lifespan_s if effective is None else effective.lifespan_s
        if math.isinf(lifespan) and effective is not None:
            lifespan = self.default_lifespan_s
        self.lifespan_s = lifespan
        deadline = math.inf if effective is None else effective.deadline_s
        if math.isinf(deadline) and self.offered is not None:
            deadline = self.offered.deadline_s
        self.deadline_s = deadline
        if effective is not None:
            self.rule = QueueRule(effective.keep, effective.best_effort)
        elif self.offered is not None or not math.isinf(lifespan):
            self.rule = QueueRule()
        else:
            self.rule = None

    def excluded_text(self, spelling: str) -> str:
        """The warning a client gets when its subscription is left out (D64)."""
        offered = self.offered
        offer = "" if offered is None else offered.describe()
        return (
            f"{spelling} offers {offer}, incompatible with this subscription"
            f" ({'; '.join(self.reasons)}): no message reaches it while that offer"
            " stands, as in ROS 2"
        )

    def deadline_text(self, spelling: str) -> str:
        """The warning a client gets when its topic misses the deadline (D65)."""
        return f"{spelling} missed its deadline: no message for {format_seconds(self.deadline_s)}"
