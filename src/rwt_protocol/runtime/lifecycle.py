"""A session's lifecycle: its states and the transitions allowed between them, in one table.

After websockets' ``State`` and h11's transition tables: the session is in
exactly one ``State``, and moves only along ``TRANSITIONS``; anything else is a
bug in the caller (``LocalProtocolError``), never silently accepted.

::

    AUTHENTICATING ──auth admitted──► OPEN
          │                            │
          ├──────────────┬─────────────┤
          ▼              ▼             ▼
       DRAINING ──► CLOSING ──────► CLOSED
          └──────────────────────────► ▲

``AUTHENTICATING`` and ``OPEN`` take input; ``DRAINING`` (the server is
stopping, D4: callers still hear back) sends but takes no input; ``CLOSING``
(a close was requested) neither takes input nor queues output; ``CLOSED``
(the connection is gone) holds nothing.
"""

from __future__ import annotations

from enum import Enum

from ..errors import LocalProtocolError

__all__ = ["TRANSITIONS", "State", "advance"]


class State(Enum):
    """Where one server-side connection is in its life (``Session.state``)."""

    AUTHENTICATING = "authenticating"
    """An authenticator is configured and the first op, an ``auth``, has not come (D23)."""
    OPEN = "open"
    """Ops are served."""
    DRAINING = "draining"
    """The server is stopping: input is ignored, replies still go out (``begin_shutdown``)."""
    CLOSING = "closing"
    """A close was requested (``request_close``): input ignored, nothing more queued."""
    CLOSED = "closed"
    """The connection is gone and released everything it held (``close``)."""

    @property
    def takes_input(self) -> bool:
        """Whether frames from the peer are handled in this state."""
        return self in (State.AUTHENTICATING, State.OPEN)

    @property
    def sends(self) -> bool:
        """Whether frames for the peer are still queued in this state."""
        return self in (State.AUTHENTICATING, State.OPEN, State.DRAINING)


TRANSITIONS: dict[State, frozenset[State]] = {
    State.AUTHENTICATING: frozenset({State.OPEN, State.DRAINING, State.CLOSING, State.CLOSED}),
    State.OPEN: frozenset({State.DRAINING, State.CLOSING, State.CLOSED}),
    State.DRAINING: frozenset({State.CLOSING, State.CLOSED}),
    State.CLOSING: frozenset({State.CLOSED}),
    State.CLOSED: frozenset(),
}
"""The states each state may move to; every move of a session goes through ``advance``."""


def advance(current: State, target: State) -> State:
    """Check one move of the lifecycle and return the new state.

    Raises:
        LocalProtocolError: ``TRANSITIONS`` has no move from ``current`` to
            ``target`` (a bug in the session or in the code driving it).
    """
    if target not in TRANSITIONS[current]:
        raise LocalProtocolError(f"session: no transition from {current.name} to {target.name}")
    return target
