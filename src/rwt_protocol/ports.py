"""The interface between the protocol session and whatever graph backs it.

``rwt_protocol`` cannot import the graph (layering, STYLE.md), so the session
talks to a ``GraphPort`` and the graph calls back into a ``TopicSink``. Both are
structural ``typing.Protocol`` types; ``rwt_graph.Graph`` implements the port.
All calls are synchronous and never block: the graph is in-memory.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping
from typing import Protocol, TypeVar

__all__ = ["ClientId", "GraphPort", "MessageCodec", "MessageEvent", "TopicSink"]

ClientId = str
"""Opaque identity of one connection (or in-process participant) in the graph."""


class MessageCodec(Protocol):
    """What the encoders need from a message's type (the graph provides it).

    The protocol layer cannot read message types (layering), yet CBOR needs each
    numeric array's element type (REF §3.2) and cbor-raw needs the dialect's wire
    serialization (REF §3.5). ``rwt_graph`` implements this per message type.
    """

    def typed(self, msg: Mapping[str, object]) -> Mapping[str, object]:
        """Return ``msg`` with every numeric array as a numpy array of its element type.

        ``uint8[]``/``char[]`` stay ``bytes``; ``bool[]`` and ``string[]`` stay lists;
        ROS 2 ``byte[]`` becomes ``uint8``. The result is only read (CBOR encoding).
        """

    def serialize(self, msg: Mapping[str, object]) -> bytes:
        """The dialect's wire form: CDR with its 4-byte header (ROS 2), or ROS 1 serialization."""


_T = TypeVar("_T")


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
        stamp: wall-clock seconds since the epoch when it was published (the
            ``secs``/``nsecs`` of cbor-raw, REF §3.5).
        codec: the message type's encoder support, or None when the publisher
            gave none (CBOR then sends plain arrays and cbor-raw is refused).
    """

    __slots__ = ("_cache", "codec", "encodings_made", "msg", "now", "stamp", "topic", "type_name")

    def __init__(
        self,
        topic: str,
        type_name: str,
        msg: dict[str, object],
        now: float,
        *,
        stamp: float = 0.0,
        codec: MessageCodec | None = None,
    ) -> None:
        self.topic = topic
        self.type_name = type_name
        self.msg = msg
        self.now = now
        self.stamp = stamp
        self.codec = codec
        self.encodings_made = 0
        self._cache: dict[Hashable, object] = {}

    def encoded(self, key: Hashable, make: Callable[[], _T]) -> _T:
        """Return the delivery form for ``key``, making it on first use.

        ``key`` names everything the form depends on (encoding, topic spelling,
        fragment size); each call of ``make`` counts in ``encodings_made``.
        """
        if key in self._cache:
            return self._cache[key]  # type: ignore[return-value]
        value = self._cache[key] = make()
        self.encodings_made += 1
        return value

    def memo(self, key: Hashable, make: Callable[[], _T]) -> _T:
        """Like ``encoded`` for an intermediate form (not counted in ``encodings_made``)."""
        if key in self._cache:
            return self._cache[key]  # type: ignore[return-value]
        value = self._cache[key] = make()
        return value


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
