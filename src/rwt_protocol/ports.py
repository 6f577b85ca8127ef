"""The interface between the protocol session and whatever graph backs it.

``rwt_protocol`` cannot import the graph (layering, STYLE.md), so the session
talks to a ``GraphPort`` and the graph calls back into a ``TopicSink``. Both are
structural ``typing.Protocol`` types; ``rwt_graph.Graph`` implements the port.
All calls are synchronous and never block: the graph is in-memory.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Protocol

__all__ = ["ClientId", "GraphPort", "MessageEvent", "TopicSink"]

ClientId = str
"""Opaque identity of one connection (or in-process participant) in the graph."""


class MessageEvent:
    """One message published on a topic, shared by every subscriber.

    Subscribers encode through ``encoded`` so that a message published to N
    subscribers is serialized once per distinct encoding (issue 4 "encode once").

    Attributes:
        topic: resolved topic name (``/chatter``).
        type_name: canonical message type (``std_msgs/msg/String``).
        msg: the message in the graph's internal form (a dict; ``bytes`` for
            ``uint8[]``), never mutated after publication.
        now: monotonic seconds when it was published.
    """

    __slots__ = ("_cache", "msg", "now", "topic", "type_name")

    def __init__(self, topic: str, type_name: str, msg: dict[str, object], now: float) -> None:
        self.topic = topic
        self.type_name = type_name
        self.msg = msg
        self.now = now
        self._cache: dict[Hashable, bytes] = {}

    def encoded(self, key: Hashable, make: Callable[[], bytes]) -> bytes:
        """Return the cached encoding for ``key``, making it on first use."""
        frame = self._cache.get(key)
        if frame is None:
            frame = self._cache[key] = make()
        return frame

    @property
    def encodings_made(self) -> int:
        """How many distinct encodings were made so far (for tests and benchmarks)."""
        return len(self._cache)


class TopicSink(Protocol):
    """Receives the messages of one topic for one subscriber."""

    def on_message(self, event: MessageEvent) -> None:
        """Take one message; must not block or raise."""


class GraphPort(Protocol):
    """What a server session needs from the graph (spec 3.3.1-3.3.5).

    Every method raises ``rwt_protocol.errors.GraphError`` (or a subclass) for a
    request the graph refuses; the session reports it as a ``status``.
    """

    def advertise(self, client: ClientId, topic: str, type_name: str, *, latch: bool) -> str:
        """Register ``client`` as a publisher; return the topic's canonical type."""

    def unadvertise(self, client: ClientId, topic: str) -> None:
        """Remove ``client`` as a publisher of ``topic``."""

    def publish(
        self, client: ClientId, topic: str, msg: object, *, latch: bool, path: str
    ) -> tuple[str, ...]:
        """Validate and publish ``msg``; return the paths of fields filled with defaults.

        ``path`` is the JSON path of ``msg`` in the op, for error texts (``$.msg``).
        """

    def subscribe(
        self, client: ClientId, topic: str, type_name: str | None, sink: TopicSink
    ) -> str:
        """Attach ``sink`` for ``client`` (replacing an earlier one); return the canonical type."""

    def unsubscribe(self, client: ClientId, topic: str) -> None:
        """Detach ``client``'s sink from ``topic``."""

    def release(self, client: ClientId) -> None:
        """Drop everything ``client`` holds (it disconnected)."""
