"""Closing connections that say nothing and hold nothing (docs/limits.md, per server).

A connection slot is a server-wide resource; one a peer opened and then left
silent (a half-open TCP socket, an abandoned page, a slot hoarder) would hold it
for ever. A connection is idle when, for ``--idle-timeout`` seconds, its peer sent
no frame **and** it held nothing in the graph: no subscription, advertisement,
offered service or action, goal, call or goal waiting for its reply, or
incomplete fragmented message (``SessionBase.holds_anything`` says it for each
protocol: a Foxglove client's subscriptions, client channels and calls count).
So a roslibpy or roslibjs client that subscribes and only listens is never cut,
nor one that publishes or serves rarely; a
client that holds nothing and stays silent is closed with a reason.

Nothing here reads a clock: the session's timer drives the checks, one per
``timeout_s`` at most (input only records its time, so the hot path costs one
assignment).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .commands import CloseCode

if TYPE_CHECKING:
    from .contract import WatchedSession
    from .timers import Timer

__all__ = ["IdleWatch"]


class IdleWatch:
    """Closes ``session`` after ``timeout_s`` seconds without input while it holds nothing.

    Args:
        session: the connection watched.
        timeout_s: seconds (``--idle-timeout``), above 0.
    """

    __slots__ = ("_session", "_timer", "last_input", "timeout_s")

    def __init__(self, session: WatchedSession, timeout_s: float) -> None:
        self._session = session
        self.timeout_s = timeout_s
        self.last_input = 0.0
        self._timer: Timer | None = None

    def start(self, now: float) -> None:
        """The connection is served from ``now`` (monotonic seconds): count from there."""
        self.last_input = now
        self._timer = self._session.call_at(now + self.timeout_s, self._check)

    def _check(self, now: float) -> None:
        self._timer = None
        session = self._session
        due = self.last_input + self.timeout_s
        if now < due or session.holds_anything():  # input since, or it holds something
            self._timer = session.call_at(max(due, now + self.timeout_s), self._check)
            return
        reason = f"idle: no input for {self.timeout_s:g} s and nothing held"
        session.request_close(CloseCode.NORMAL, reason)
