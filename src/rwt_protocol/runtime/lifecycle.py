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
(the connection is gone) holds nothing. ``Lifecycle`` is the part of
``connection.SessionBase`` that moves through them and asks its transport to close.
"""

from __future__ import annotations

import logging
from enum import Enum
from typing import TYPE_CHECKING

from ..errors import LocalProtocolError
from .commands import CloseCode, CloseConnection, Command

if TYPE_CHECKING:
    from ..ports import ClientId

__all__ = ["TRANSITIONS", "Lifecycle", "State", "advance"]

logger = logging.getLogger("rwt.session")


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


class Lifecycle:
    """A session's life (the module's text): its state and the close it asks for.

    A part of ``connection.SessionBase``, which releases what the client held
    (``release``) and wakes its transport (``_wake``).
    """

    _state: State
    _sends: bool
    _commands: list[Command]
    _close_request: CloseConnection | None
    _client_id: ClientId

    if TYPE_CHECKING:  # the session's other parts, which its life calls

        def release(self) -> None:
            """Drop what the client holds in the graph (``SessionBase.release``)."""
            raise NotImplementedError

        def _wake(self) -> None:
            """Wake the transport (``sender.Sender._wake``)."""
            raise NotImplementedError

    def request_close(self, code: CloseCode, reason: str, *, abort: bool = False) -> None:
        """Ask the transport to close: queue ``CloseConnection`` after the frames queued so far.

        Later input is ignored and later frames are not queued. Idempotent: only
        the first request counts.

        Args:
            code: the close code (WebSocket; logged on other transports).
            reason: why, for the peer and the log.
            abort: the peer is not reading (slow consumer): cut without waiting.
        """
        if self._state in (State.CLOSING, State.CLOSED):
            return
        self._move(State.CLOSING)
        self._close_request = CloseConnection(code, reason, abort)
        logger.log(
            logging.DEBUG if code is CloseCode.NORMAL else logging.INFO,
            "event=closing client=%s code=%d reason=%r",
            self._client_id,
            code,
            reason,
        )
        self._commands.append(self._close_request)
        self._wake()

    def begin_shutdown(self) -> None:
        """The server is stopping: ignore further input and release what this client holds.

        Releasing first lets the graph answer callers waiting on this client
        (D4) while their connections can still send; the server then calls
        ``request_close(CloseCode.GOING_AWAY, ...)`` on every session.
        """
        if self._state is State.CLOSED:
            return
        if self._state.takes_input:
            self._move(State.DRAINING)
        self.release()

    def commands_to_run(self) -> list[Command]:
        """Take every command queued for the transport."""
        commands, self._commands = self._commands, []
        return commands

    @property
    def close_request(self) -> CloseConnection | None:
        """The close this session asked for, if any (also while the transport has it)."""
        return self._close_request

    @property
    def state(self) -> State:
        """Where the connection is in its life (``lifecycle.State``, its moves in one table)."""
        return self._state

    @property
    def closed(self) -> bool:
        """Whether ``close`` was called (``state`` is CLOSED)."""
        return self._state is State.CLOSED

    @property
    def closing(self) -> bool:
        """Whether the session stopped taking input (close requested, shutting down, closed)."""
        return not self._state.takes_input

    def _move(self, target: State) -> None:
        """Change ``state`` along ``lifecycle.TRANSITIONS``; LocalProtocolError otherwise."""
        self._state = advance(self._state, target)
        self._sends = self._state.sends
