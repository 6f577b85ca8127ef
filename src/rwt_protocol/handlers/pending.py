"""Handlers of ops this server does not serve yet.

Each is refused with an error status (D1); where the op has a natural failure
reply, that is sent too, so a caller never waits forever (PROTOCOL-DECISIONS D4).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..errors import RemoteProtocolError
from ..ops import CallService, OpModel, SendActionGoal

if TYPE_CHECKING:
    from ..session import Session

__all__ = ["refuse", "refuse_call_service", "refuse_send_action_goal"]


def refuse(session: Session, op: OpModel, now: float) -> None:
    """Refuse an op that is not supported yet.

    Raises:
        RemoteProtocolError: always.
    """
    raise RemoteProtocolError("not supported by this server yet")


def refuse_call_service(session: Session, op: CallService, now: float) -> None:
    """Answer a service call with ``result:false`` (D4, D28), then refuse it."""
    reply: dict[str, object] = {
        "op": "service_response",
        "service": op.service,
        "values": "services are not supported by this server yet",
        "result": False,
    }
    if op.id is not None:
        reply["id"] = op.id
    session.send_op(reply)
    refuse(session, op, now)


def refuse_send_action_goal(session: Session, op: SendActionGoal, now: float) -> None:
    """Answer a goal with an aborted ``action_result`` (D4, D18), then refuse it."""
    reply: dict[str, object] = {
        "op": "action_result",
        "action": op.action,
        "values": "actions are not supported by this server yet",
        "status": 6,
        "result": False,
    }
    if op.id is not None:
        reply["id"] = op.id
    session.send_op(reply)
    refuse(session, op, now)
