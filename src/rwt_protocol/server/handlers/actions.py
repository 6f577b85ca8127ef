"""Handlers of the action ops (spec 3.3.10-3.3.15, D4, D15, D18)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...errors import GraphError, RemoteProtocolError, RwtError
from ...levels import StatusLevel
from ...names import resolve_name
from ...ops import (
    ActionFeedback,
    ActionResult,
    AdvertiseAction,
    CancelActionGoal,
    SendActionGoal,
    UnadvertiseAction,
)
from ...ports import GoalStatus
from ..compat import reply_text
from .topics import report_type_warning

if TYPE_CHECKING:
    from .context import HandlerContext

__all__ = [
    "action_feedback",
    "action_result",
    "advertise_action",
    "cancel_action_goal",
    "send_action_goal",
    "unadvertise_action",
]


def advertise_action(session: HandlerContext, op: AdvertiseAction, now: float) -> None:
    """Offer an action provided by this client (spec 3.3.10; newest wins, D15).

    Raises:
        GraphError: bad or unknown action type.
    """
    name = resolve_name(op.action)
    holdings = session.holdings
    if ("action", name) not in holdings.offers:
        session.check_cap(holdings.offered(), session.config.max_advertisements, "advertisements")
    type_name = session.graph.advertise_action(
        session.client_id, op.action, op.type, session.provider_link
    )
    holdings.add_offer("action", name)
    report_type_warning(session, "advertise_action", type_name, None)
    session.report(StatusLevel.INFO, f"advertise_action: {op.action} advertised as {type_name}")


def unadvertise_action(session: HandlerContext, op: UnadvertiseAction, now: float) -> None:
    """Withdraw an action of this client; its goals abort (spec 3.3.11).

    Raises:
        GraphError: this client does not provide the action.
    """
    session.graph.unadvertise_action(session.client_id, op.action)
    session.holdings.drop_offer("action", resolve_name(op.action))
    session.report(StatusLevel.INFO, f"unadvertise_action: {op.action} unadvertised")


def send_action_goal(session: HandlerContext, op: SendActionGoal, now: float) -> None:
    """Send a goal; feedback (when asked) and one result follow (spec 3.3.12, D18).

    A refused goal is answered with ``action_result`` ``result: false``, status 6
    (D4) and a status. ``action_type`` is not checked against the server's type
    (clients name the same action in different packages, REF §7.3).

    Raises:
        RwtError: the action does not exist or ``args`` does not fit.
    """
    key = op.id
    finished = False

    def done(status: GoalStatus, result: bool, values: object) -> None:
        nonlocal finished
        if finished:
            return
        finished = True
        if handle is not None:  # counted in the holdings' pending goals
            session.holdings.goal_finished(key, handle)
        reply = ActionResult(
            action=op.action, id=op.id, result=result, values=values, status=int(status)
        )
        session.send(reply, compression=op.compression, fragment_size=op.fragment_size)

    def feedback(values: dict[str, object]) -> None:
        message = ActionFeedback(action=op.action, id=op.id, values=values)
        session.send(message, compression=op.compression, fragment_size=op.fragment_size)

    handle = None
    try:
        pending = session.holdings.pending_goals
        session.check_cap(pending, session.config.max_pending_goals, "pending goals")
        handle = session.graph.send_action_goal(
            session.client_id,
            op.action,
            op.args,
            done,
            feedback if op.feedback else None,
            path="$.args",
            request_id=None if op.id is None else str(op.id),
        )
    except RwtError as exc:
        done(GoalStatus.ABORTED, False, reply_text(session.config.compat, exc))
        raise
    if not finished:
        session.holdings.goal_started(key, handle)


def cancel_action_goal(session: HandlerContext, op: CancelActionGoal, now: float) -> None:
    """Ask to cancel the goal ``op.id`` of ``op.action`` (spec 3.3.13, D35).

    This connection's own goal with that id first; else the newest goal in
    flight on the action with that id, sent by any connection (also one that
    closed), as rosbridge_suite's goal table is shared. The access rules have
    allowed the action already (``AccessPolicy.check``).

    Raises:
        GraphError: warning when no goal with that id is in progress.
    """
    handle = session.holdings.goals.get(op.id)
    if handle is not None:
        handle.request_cancel()
        return
    if op.id is None:
        raise GraphError("no goal None in progress", level=StatusLevel.WARNING)
    session.graph.cancel_action_goal(session.client_id, op.action, str(op.id))


def action_feedback(session: HandlerContext, op: ActionFeedback, now: float) -> None:
    """Feedback for a goal this client's action received (spec 3.3.14).

    Raises:
        RemoteProtocolError: no ``id``.
        GraphError: not this client's action, or no such goal (warning).
        FieldError: ``values`` does not fit the feedback type.
    """
    if op.id is None:
        raise RemoteProtocolError("missing field at $.id")
    session.graph.action_feedback(session.client_id, op.action, op.id, op.values, path="$.values")


def action_result(session: HandlerContext, op: ActionResult, now: float) -> None:
    """The result of a goal this client's action received (spec 3.3.15, D18).

    Raises:
        RemoteProtocolError: no ``id``.
        GraphError: not this client's action, no such goal, or a bad status.
        FieldError: ``values`` does not fit the result type.
    """
    if op.id is None:
        raise RemoteProtocolError("missing field at $.id")
    session.graph.action_result(
        session.client_id,
        op.action,
        op.id,
        op.result,
        op.values,
        status=op.status,
        path="$.values",
    )
