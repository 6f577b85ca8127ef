"""Natural failure replies: what a refused request gets besides its status (D4).

A ``call_service`` is answered with a failed ``service_response`` and a
``send_action_goal`` with an aborted ``action_result``, so a caller never waits
forever, whichever part of the server refused the op (access rules, a missing
service, a closed connection).
"""

from __future__ import annotations

from .ops import CallService, OpModel, SendActionGoal

__all__ = ["GOAL_ABORTED", "failure_reply"]

GOAL_ABORTED = 6
"""``action_msgs/GoalStatus`` STATUS_ABORTED, the ``status`` of a refused goal (D4, D28)."""


def failure_reply(op: OpModel, text: str) -> dict[str, object] | None:
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
    reply: dict[str, object]
    if isinstance(op, CallService):
        reply = {"op": "service_response", "service": op.service, "values": text, "result": False}
    elif isinstance(op, SendActionGoal):
        reply = {
            "op": "action_result",
            "action": op.action,
            "values": text,
            "status": GOAL_ABORTED,
            "result": False,
        }
    else:
        return None
    if op.id is not None:
        reply["id"] = op.id
    return reply
