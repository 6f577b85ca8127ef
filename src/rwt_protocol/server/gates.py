"""The two gates every op passes before its handler: authentication and access rules.

- Authentication (ROS 1 edition 3.3.1, D23): with an
  authenticator configured, the first op must be an ``auth`` it admits; any
  other op first, or a refused ``auth``, gets an error status and the
  connection is closed (the session does both).
- Access rules (``AccessPolicy``, rosbridge's ``*_glob`` parameters): a denied
  op gets an error status and, for calls and goals, its failure reply (D1, D4).

Both log a structured line (``event=auth_failed``; ``event=access_denied``, the
one access gate's, ``runtime.access.log_denied``) once per episode of refusals,
repeats counted (``ratelog.EpisodeLog``): a client repeating them cannot write the
log at its own rate. The ``auth`` op is checked by the one check of auth ops
(``credentials.op_refusal``), which URL tokens go through too.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from ..credentials import op_refusal
from ..errors import RemoteProtocolError
from ..levels import StatusLevel
from ..ops import Auth, OpModel, PublishView
from ..ratelog import EpisodeLog
from ..runtime.access import AccessDeniedError, log_denied
from .op_access import check_op
from .replies import failure_reply

if TYPE_CHECKING:
    from .session import Session

__all__ = ["AUTH_REQUIRED", "FIRST_OP_NOT_AUTH", "authenticate", "check_access"]

logger = logging.getLogger("rwt.session")
_episodes = EpisodeLog(logger)  # no clock here: each line passes the session's time

AUTH_REQUIRED = "authentication required"
"""What an op refused for want of authentication is told (a call's failure reply, D4)."""

FIRST_OP_NOT_AUTH = f"{AUTH_REQUIRED}: the first op must be auth"
"""The error status of a first op that is not ``auth`` (D23)."""


def authenticate(session: Session, op: OpModel) -> bool:
    """Decide the first op of a connection that must authenticate (D23).

    Returns:
        True when ``op`` is an ``auth`` the authenticator admits.

    Raises:
        RemoteProtocolError: the op is not ``auth``, or it was refused; the
            session reports it and closes the connection. A call or goal is
            answered with its failure reply first (D4).
    """
    if not isinstance(op, Auth):
        reply = failure_reply(op, AUTH_REQUIRED)
        if reply is not None:
            session.send(reply)
        _failed(session, f"first op was {op.op}")
        raise RemoteProtocolError(FIRST_OP_NOT_AUTH)
    authenticator = session.config.authenticator
    if authenticator is None:  # pragma: no cover - the session only asks when there is one
        return True
    # the one check of an auth op (credentials.py), the URL token's too
    why = op_refusal(authenticator, op, session.peer, nonce=session.auth_nonce, now=session.now)
    if why is not None:
        _failed(session, why)
        raise RemoteProtocolError("authentication failed")
    logger.info(
        "event=auth_ok client=%s peer=%s level=%s", session.client_id, session.peer, op.level
    )
    session.report(StatusLevel.INFO, "auth: authenticated")
    return True


def check_access(session: Session, op: OpModel | PublishView) -> None:
    """Refuse an op the access rules deny, answering a call or goal (D4).

    Raises:
        AccessDeniedError: the op names a topic, service, action or parameter
            outside the rules.
    """
    try:
        check_op(session.config.access, op)
    except AccessDeniedError as exc:
        name: str = op.op
        log_denied(exc, client=session.client_id, op=name, now=session.now)  # the one log line
        reply = failure_reply(op, f"{name}: {exc.message}") if isinstance(op, OpModel) else None
        if reply is not None:
            session.send(reply)
        raise


def _failed(session: Session, reason: str) -> None:
    _episodes.log(
        logging.WARNING,
        "auth_failed",
        "event=auth_failed client=%s peer=%s reason=%r",
        session.client_id,
        session.peer,
        reason,
        now=session.now,
    )
