"""Handlers of set_level, status and auth (spec 3.2, ROS 1 edition 3.3)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...errors import RemoteProtocolError
from ...levels import StatusLevel

if TYPE_CHECKING:
    from ...ops import Auth, OpModel, SetLevel, Status
    from .context import HandlerContext

__all__ = ["auth", "not_supported", "set_level", "status"]


def set_level(session: HandlerContext, op: SetLevel, now: float) -> None:
    """Change which status messages this connection receives (spec 3.2.1, D2).

    A level outside the four is rejected by the op model, leaving the level as it was.
    """
    session.set_status_level(StatusLevel.from_wire(op.level))
    session.report(StatusLevel.INFO, f"set_level: status level is {op.level}", op.id)


def status(session: HandlerContext, op: Status, now: float) -> None:
    """A client's status message: nothing to do (status flows server to client)."""


def auth(session: HandlerContext, op: Auth, now: float) -> None:
    """Credentials after the first op, or on a server without authentication: ignored.

    The authentication gate itself (D23) is in the session; this handler only
    sees ``auth`` ops it let through (ROS 1 spec 3.3.1).
    """
    if session.config.authenticator is None:
        session.report(StatusLevel.INFO, "auth: authentication is not enabled; ignored")
    else:
        session.report(StatusLevel.INFO, "auth: already authenticated; ignored")


def not_supported(session: HandlerContext, op: OpModel, now: float) -> None:
    """Refuse an op this server does not serve yet.

    Raises:
        RemoteProtocolError: always.
    """
    raise RemoteProtocolError("not supported by this server yet")
