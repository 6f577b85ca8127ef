"""Slow consumers (D24, REF §9.1): report once, close if stalled; for every protocol.

The outbox drops the oldest topic messages above its limit. This watch turns
that into what a user sees: the first drop of an episode is logged
(``event=slow_consumer``) and reported as a ``warning`` status, and a timer
checks every ``send_timeout_s`` whether the transport took any frame since; if
it did not, the peer has stopped reading and the connection is closed (abort:
nothing more can be delivered). The episode ends when the transport catches up
to the high watermark (half the limit); the session is told (``dropping_over``:
a Foxglove client's warning is withdrawn). How the peer is told is its
protocol's (``SessionBase.warn_dropping``); the rule is the same for all.

A message larger than the whole limit goes out when no other topic message
waits (the outbox holds it alone); one that came while others waited was
dropped (``Outbox.dropped_oversized``). The peer is told once, with a
``warning`` naming ``--send-buffer-limit`` (raising it is the only way to get
every such message to a peer that falls behind), and told again only after a
message over the limit went out to it since; the server logs
``event=oversized_dropped`` once per connection (then at debug level). Such a
drop also starts an episode, so a peer that reads nothing is still closed.

The server's memory budget (``memory``, D44) applies the same rule to every
connection while it is full: drops it makes start an episode as above (the
warning then names ``--memory-budget``), and a connection holding more than
``memory.PRESSURE_FLOOR_BYTES`` that takes nothing for ``send_timeout_s`` is
closed (``memory_pressed``), whatever it holds: a client that does not read
cannot keep its replies or an asset file in a full server's memory.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from ..levels import StatusLevel
from .commands import CloseCode
from .memory import MEMORY_BUDGET_OPTION

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from .contract import WatchedSession
    from .outbox import Outbox, OutFrame
    from .timers import Timer

__all__ = ["SEND_BUFFER_OPTION", "SlowConsumerWatch", "lost_text"]

logger = logging.getLogger("rwt.session")

SEND_BUFFER_OPTION = "--send-buffer-limit"
"""The option that sets ``ClientRules.send_buffer_limit``, named to a peer that needs it."""


def lost_text(count: int, topic: str) -> str:
    """What a subscriber of ``topic`` is told when ``count`` of its messages were lost.

    Lost on the way to the server (``rwt_protocol.ports.LossSink``, D61), as a
    ``warning`` in its protocol's words; its own drops are ``SlowConsumerWatch``'s.
    """
    plural = "s" if count != 1 else ""
    return (
        f"lost {count} message{plural} of {topic} on the way to this server: a queue "
        f"between the server's processes or a link was full"
    )


class SlowConsumerWatch:
    """Tracks one connection's episodes of being over its send buffer limit.

    Args:
        session: the session whose outbox is watched.
        outbox: that outbox.
    """

    def __init__(self, session: WatchedSession, outbox: Outbox) -> None:
        self.session = session
        self.outbox = outbox
        self.takes = 0  # how many times the transport took frames: progress
        self._timer: Timer | None = None
        self._told_slow = False  # this episode's warning went out
        self._told_oversized = False  # until a message over the limit goes out again
        self._logged_oversized = False
        self._held = False  # a message over the limit was held when last seen
        self._memory_drops = 0  # ``Outbox.dropped_memory`` when last seen
        self._stale = 0  # ``Outbox.stale`` when last seen
        self._for_memory = False  # the running timer is the memory budget's

    def after_push(
        self,
        dropped_before: int,
        oversized_before: int,
        now: float,
        frames: Sequence[OutFrame],
        topic: str | None,
    ) -> None:
        """The frames of one message were pushed: start an episode if that dropped or went over.

        A message past its lifespan when it came (``Outbox.stale``) is not a drop
        here: its subscription asked for that (D63), and the peer may read fast.

        Args:
            dropped_before: ``Outbox.dropped`` before they were pushed.
            oversized_before: ``Outbox.dropped_oversized`` before they were pushed.
            now: the session's time, monotonic seconds.
            frames: the message's frames.
            topic: the topic of a message, as the peer spells it; None for an op.
        """
        outbox = self.outbox
        oversized = outbox.dropped_oversized > oversized_before
        stale = outbox.stale - self._stale  # past their lifespan when they came (D63)
        self._stale = outbox.stale
        dropped = outbox.dropped - dropped_before - stale
        others = dropped > outbox.dropped_oversized - oversized_before
        if outbox.held_bytes:
            self._held = True
        if oversized:
            self._oversized_dropped(topic, sum(len(frame.data) for frame in frames))
        slow = others or outbox.over_limit
        if not (slow or oversized):
            return
        session = self.session
        if self._timer is None:
            self._start_timer(now)
        if not slow or self._told_slow:
            return
        self._told_slow = True
        for_memory = outbox.dropped_memory != self._memory_drops
        self._memory_drops = outbox.dropped_memory
        logger.warning(
            "event=slow_consumer client=%s protocol=%s limit_bytes=%d dropped_total=%d%s",
            session.client_id,
            session.protocol,
            outbox.limit_bytes,
            dropped_before,
            " reason=memory_budget" if for_memory else "",
        )
        bound = (
            self._bound_text() if for_memory else f"send buffer limit {outbox.limit_bytes} bytes"
        )
        session.warn_dropping(
            f"dropping the oldest topic messages: this connection reads slower than they "
            f"arrive ({bound})"
        )

    def memory_pressed(self, now: float) -> None:
        """The server's memory budget is full and this connection holds much (D44).

        Unless a check runs already, it is closed if it takes nothing for
        ``send_timeout_s`` from ``now`` (monotonic seconds).
        """
        if self._timer is None:
            self._start_timer(now, for_memory=True)

    def _start_timer(self, now: float, *, for_memory: bool = False) -> None:
        session = self.session
        self._for_memory = for_memory
        self._timer = session.call_at(now + session.config.send_timeout_s, self._check(self.takes))

    def _bound_text(self) -> str:
        """The memory budget's words for a peer: the budget full, and its option."""
        account = self.outbox.account
        limit = 0 if account is None else account.budget.limit
        return f"the server's memory budget is full, {MEMORY_BUDGET_OPTION} {limit} bytes"

    def after_take(self) -> None:
        """The transport took frames: progress; the episode ends once it caught up."""
        self.takes += 1
        outbox = self.outbox
        if self._held and not outbox.held_bytes:  # a message over the limit went out
            self._held = self._told_oversized = False
        if self._timer is not None and outbox.fill_bytes <= outbox.high_water_bytes:
            self._timer.cancel()
            self._timer = None
            if self._told_slow:
                self._told_slow = False
                self.session.dropping_over()

    def _oversized_dropped(self, topic: str | None, size: int) -> None:
        """Log the drop of a message over the limit; tell the peer unless told already."""
        session = self.session
        limit = self.outbox.limit_bytes
        level = logging.WARNING if not self._logged_oversized else logging.DEBUG
        self._logged_oversized = True
        logger.log(
            level,
            "event=oversized_dropped client=%s topic=%s bytes=%d limit_bytes=%d dropped_total=%d",
            session.client_id,
            topic,
            size,
            limit,
            self.outbox.dropped,
        )
        if self._told_oversized:
            return
        self._told_oversized = True
        where = f" of {topic}" if topic is not None else ""
        session.report(
            StatusLevel.WARNING,
            f"dropped a {size}-byte message{where}: larger than the send buffer limit "
            f"({SEND_BUFFER_OPTION} {limit} bytes), such a message goes out only when no "
            f"other topic message waits for this connection, and this connection was behind",
        )

    def _check(self, takes: int) -> Callable[[float], None]:
        def check(now: float) -> None:
            session = self.session
            if self.takes != takes:  # still full, but the peer is reading: look again later
                if self._for_memory:  # the budget's next sweep looks again if need be
                    self._timer = None
                    return
                self._start_timer(now)
                return
            self._timer = None
            timeout = session.config.send_timeout_s
            if self._for_memory:
                account = self.outbox.account
                held = self.outbox.queued_bytes if account is None else account.held
                reason = (
                    f"slow consumer: {held} bytes unread for {timeout:g} s "
                    f"while {self._bound_text()}"
                )
            else:
                reason = (
                    f"slow consumer: send buffer over {self.outbox.limit_bytes} bytes "
                    f"for {timeout:g} s"
                )
            session.request_close(CloseCode.POLICY_VIOLATION, reason, abort=True)

        return check
