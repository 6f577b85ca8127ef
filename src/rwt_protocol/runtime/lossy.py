"""A session's lossy lane: the latest message of each topic, for an unreliable channel.

A transport with a second, unreliable and unordered channel beside the
session's reliable one (WebRTC's ``rosbridge-lossy`` data channel, D36,
docs/webrtc.md) opens a lane on the session (``contract.LossySession``, which every
``SessionBase`` is: ``open_lossy_lane``). The topic messages of the subscriptions
made on that channel then go here rather than to the outbox: one message per topic
waits at most, a newer one replacing the unsent older one (latest-only), and the
transport takes them when its channel has room (``pop``). Replies, statuses and every other
subscription's messages stay on the outbox and the reliable channel.

Bounds (docs/limits.md): a message above ``max_message_bytes`` (the peer's
``max-message-size``: the lane sends no fragments) is refused, and the lane
holds at most ``limit_bytes`` of messages (the connection's send buffer
limit), its oldest topics' messages dropped past it. A message may come with
the end of its lifespan (``put``'s ``expires``, D63): it is not taken after it
(``pop``'s ``now``), and counts as ``expired``. Nothing here awaits or reads a
clock.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

    from .outbox import OutFrame

__all__ = ["LossyLane"]


class LossyLane:
    """The latest unsent message of each topic subscribed on a lossy channel.

    Args:
        max_message_bytes: the largest message the channel carries, bytes (the
            peer's ``max-message-size``; 0: any size).
        limit_bytes: the most payload bytes held over all topics; past it the
            oldest topics' messages are dropped.
        on_output: called (synchronously, without arguments) when the lane goes
            from empty to holding a message, so the transport can wake its writer.

    Attributes:
        queued: messages put so far (refused ones excluded).
        replaced: messages replaced by a newer one of their topic before they were sent.
        dropped: messages dropped past ``limit_bytes``.
        refused: messages over ``max_message_bytes``, never queued.
        expired: messages past their lifespan when their turn came, never sent.
    """

    def __init__(
        self, max_message_bytes: int, limit_bytes: int, on_output: Callable[[], None]
    ) -> None:
        self.max_message_bytes = max_message_bytes
        self.limit_bytes = limit_bytes
        self._on_output = on_output
        self._latest: dict[str, OutFrame] = {}
        self._expires: dict[str, float] = {}  # the topics whose message has a lifespan
        self._bytes = 0
        self.queued = 0
        self.replaced = 0
        self.dropped = 0
        self.refused = 0
        self.expired = 0

    def __len__(self) -> int:
        return len(self._latest)

    @property
    def queued_bytes(self) -> int:
        """Payload bytes of the messages waiting."""
        return self._bytes

    def fits(self, size: int) -> bool:
        """Whether a message of ``size`` bytes may go on the lane (``max_message_bytes``)."""
        return not self.max_message_bytes or size <= self.max_message_bytes

    def put(self, topic: str, frame: OutFrame, expires: float = math.inf) -> bool:
        """Queue ``frame`` as ``topic``'s latest message, replacing an unsent older one.

        The topic keeps its place among those waiting (the oldest topic goes first).
        ``expires``: the monotonic time after which it is not sent (D63).

        Returns:
            False when the frame is over ``max_message_bytes``: it was not queued.
        """
        size = len(frame.data)
        if not self.fits(size):
            self.refused += 1
            return False
        was_empty = not self._latest
        older = self._latest.get(topic)
        if older is not None:
            self.replaced += 1
            self._bytes -= len(older.data)
        self._latest[topic] = frame
        if math.isinf(expires):
            self._expires.pop(topic, None)
        else:
            self._expires[topic] = expires
        self._bytes += size
        self.queued += 1
        while self._bytes > self.limit_bytes and len(self._latest) > 1:
            oldest = next(iter(self._latest))
            if oldest == topic:  # the newest stays; drop the next oldest
                self._latest[topic] = self._latest.pop(topic)
                continue
            self._bytes -= len(self._latest.pop(oldest).data)
            self._expires.pop(oldest, None)
            self.dropped += 1
        if was_empty:
            self._on_output()
        return True

    def pop(self, now: float | None = None) -> OutFrame | None:
        """Take the message of the topic that waited longest; None when none waits.

        ``now``: monotonic seconds; a message whose lifespan ended before it is
        dropped (``expired``) and the next one taken.
        """
        while self._latest:
            topic = next(iter(self._latest))
            frame = self._latest.pop(topic)
            self._bytes -= len(frame.data)
            expires = self._expires.pop(topic, math.inf) if self._expires else math.inf
            if now is None or expires >= now:
                return frame
            self.expired += 1
        return None

    def clear(self) -> None:
        """Drop every waiting message (the channel or the connection closed)."""
        self._latest.clear()
        self._expires.clear()
        self._bytes = 0
