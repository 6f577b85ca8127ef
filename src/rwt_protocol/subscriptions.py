"""One client's subscriptions: several ids per topic merged into one delivery.

Spec 3.3.4 and PROTOCOL-DECISIONS D11: a client with several subscriptions to a
topic receives one copy of each message; the merged parameters are the lowest
``throttle_rate``, the lowest ``fragment_size``, the highest ``queue_length`` and
the strongest ``compression`` (``cbor-raw`` > ``cbor`` > ``png`` > ``none``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .ops import Subscribe
from .ops.base import Compression
from .ports import MessageEvent

__all__ = ["MergedParams", "TopicSubscription"]

_STRENGTH: dict[Compression, int] = {"none": 0, "png": 1, "cbor": 2, "cbor-raw": 3}

SubscriptionKey = str | int | None
"""A subscription id as sent, or None for a subscription without id."""


@dataclass(frozen=True, slots=True)
class MergedParams:
    """The effective delivery parameters of one client's topic subscriptions.

    Attributes:
        throttle_rate_ms: minimum interval between messages, milliseconds.
        queue_length: messages buffered while throttled (0 = none).
        fragment_size: largest frame before fragmenting, or None.
        compression: the encoding of delivered messages.
    """

    throttle_rate_ms: int = 0
    queue_length: int = 0
    fragment_size: int | None = None
    compression: Compression = "none"


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

    It is the ``TopicSink`` the graph calls; delivery goes through ``deliver``,
    which the session provides.

    Args:
        topic: the resolved topic name.
        spelling: the name as the client wrote it; delivered messages carry it (D26).
        deliver: called with this subscription and each message.
    """

    def __init__(
        self,
        topic: str,
        spelling: str,
        deliver: Callable[[TopicSubscription, MessageEvent], None],
    ) -> None:
        self.topic = topic
        self.spelling = spelling
        self.requests: dict[SubscriptionKey, Subscribe] = {}
        self.params = MergedParams()
        self.type_name = ""
        self._deliver = deliver

    def add(self, request: Subscribe) -> None:
        """Add or replace the subscription ``request.id`` and re-merge."""
        self.requests[request.id] = request
        self.spelling = request.topic
        self.params = merge(list(self.requests.values()))

    def remove(self, key: SubscriptionKey) -> bool:
        """Remove one subscription id; return whether it existed."""
        if key not in self.requests:
            return False
        del self.requests[key]
        if self.requests:
            self.params = merge(list(self.requests.values()))
        return True

    def on_message(self, event: MessageEvent) -> None:
        """Receive one message from the graph (``TopicSink``)."""
        self._deliver(self, event)
