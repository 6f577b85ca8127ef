"""Natural failure replies: what a refused request gets besides its status (D4).

A ``call_service`` is answered with a failed ``service_response`` and a
``send_action_goal`` with an aborted ``action_result``, so a caller never waits
forever, whichever part of the server refused the op (access rules, a missing
service, a closed connection).
"""

from __future__ import annotations

from ..ops import ActionResult, CallService, OpModel, SendActionGoal, ServiceResponse
from ..ports import GoalStatus

__all__ = ["failure_reply"]


def failure_reply(op: OpModel, text: str) -> ServiceResponse | ActionResult | None:
    """Build the failure reply of ``op``, or None for ops that have none.

    Args:
        op: the refused request.
        text: why it was refused; goes into ``values`` (D4, D28).

    Returns:
        ``service_response`` (``result: false``) for ``call_service``,
        ``action_result`` (``result: false``, ``status`` 6) for
        ``send_action_goal``, with the request's name and ``id`` exactly as sent
        (D26, D28); None otherwise.
    """
    if isinstance(op, CallService):
        return ServiceResponse(service=op.service, result=False, values=text, id=op.id)
    if isinstance(op, SendActionGoal):
        aborted = int(GoalStatus.ABORTED)
        return ActionResult(action=op.action, id=op.id, result=False, values=text, status=aborted)
    return None
