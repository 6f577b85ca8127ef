"""What the session's parts (services, parameters, connection graph) send through.

The session implements it; the parts never touch its queue, and refuse a name
through its access gate (``require_access``). A frame sent with
``tracked`` stays "unsent" until the driver took it (``FoxgloveSession.take``):
a part that sends updates (parameter changes, the connection graph) sends the
next one only then, merged, so a client that does not read holds at most one
of each (docs/limits.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.runtime.access import Family, TopicUse
    from rwt_protocol.runtime.outbox import OutFrame
    from rwt_protocol.runtime.timers import Timer

    from .protocol import ServerOp

__all__ = ["SessionOutput"]


class SessionOutput(Protocol):
    """Where a part of the session queues what it sends to the client."""

    def control(self, op: ServerOp) -> None:
        """Queue a server op that is never dropped (``advertiseServices``...)."""

    def answer(self, data: bytes, *, binary: bool) -> None:
        """Queue an answer to the client's input (never dropped: the client pays for it).

        A client that sends requests and reads nothing fills its own queue with
        their answers; its reader then waits for it, as a rosbridge client's does
        (docs/limits.md, input backpressure).
        """

    def error(self, message: str) -> None:
        """Queue an error ``status`` (an answer to the client's input, never dropped)."""

    def call_at(self, deadline: float, callback: Callable[[float], None]) -> Timer:
        """Run ``callback(now)`` once ``now >= deadline`` (monotonic seconds)."""

    @property
    def now(self) -> float:
        """The session's latest monotonic time, seconds."""

    def tracked(self, op: ServerOp) -> OutFrame:
        """Queue ``op`` (never dropped) and return its frame, for ``unsent``."""

    def unsent(self, frame: OutFrame) -> bool:
        """Whether ``frame`` (from ``tracked``) is still waiting in the queue."""

    def require_access(
        self, family: Family, name: str, op: str, use: TopicUse | None = None
    ) -> None:
        """The one access gate (``SessionBase.require_access``): refuse and log a denied name.

        Raises:
            AccessDeniedError: ``name`` is outside the server's access rules.
        """
