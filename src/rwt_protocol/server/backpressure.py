"""Slow consumers (D24, REF §9.1): report once, close if stalled.

The outbox drops the oldest topic messages above its limit. This watch turns
that into what a user sees: the first drop of an episode is logged
(``event=slow_consumer``) and reported as a ``warning`` status, and a timer
checks every ``send_timeout_s`` whether the transport took any frame since; if
it did not, the peer has stopped reading and the connection is closed (abort:
nothing more can be delivered). The episode ends when the transport catches up
to half the limit.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from ..levels import StatusLevel
from .commands import CloseCode

if TYPE_CHECKING:
    from collections.abc import Callable

    from .outbox import Outbox
    from .session import Session
    from .timers import Timer

__all__ = ["SlowConsumerWatch"]

logger = logging.getLogger("rwt.session")


class SlowConsumerWatch:
    """Tracks one connection's episodes of being over its send buffer limit.

    Args:
        session: the session whose outbox is watched.
        outbox: that outbox.
    """

    def __init__(self, session: Session, outbox: Outbox) -> None:
        self.session = session
        self.outbox = outbox
        self.takes = 0  # how many times the transport took frames: progress
        self._timer: Timer | None = None

    def after_push(self, dropped_before: int, now: float) -> None:
        """Frames were queued: start an episode if that dropped frames or went over."""
        full = self.outbox.dropped > dropped_before or self.outbox.over_limit
        if not full or self._timer is not None:
            return
        session = self.session
        self._timer = session.call_at(now + session.config.send_timeout_s, self._check(self.takes))
        logger.warning(
            "event=slow_consumer client=%s limit_bytes=%d dropped_total=%d",
            session.client_id,
            self.outbox.limit_bytes,
            dropped_before,
        )
        session.report(
            StatusLevel.WARNING,
            f"dropping the oldest topic messages: this connection reads slower than they "
            f"arrive (send buffer limit {self.outbox.limit_bytes} bytes)",
        )

    def after_take(self) -> None:
        """The transport took frames: progress; the episode ends once it caught up."""
        self.takes += 1
        if self._timer is not None and self.outbox.queued_bytes <= self.outbox.limit_bytes // 2:
            self._timer.cancel()
            self._timer = None

    def _check(self, takes: int) -> Callable[[float], None]:
        def check(now: float) -> None:
            session = self.session
            if self.takes != takes:  # still full, but the peer is reading: look again later
                self._timer = session.call_at(
                    now + session.config.send_timeout_s, self._check(self.takes)
                )
                return
            self._timer = None
            session.request_close(
                CloseCode.POLICY_VIOLATION,
                f"slow consumer: send buffer over {self.outbox.limit_bytes} bytes "
                f"for {session.config.send_timeout_s:g} s",
                abort=True,
            )

        return check
