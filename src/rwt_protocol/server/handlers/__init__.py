"""The dispatcher table: op model -> handler (a table, not an if/elif chain).

A handler is ``handler(context, op, now) -> None``, where ``context`` is the
connection as handlers see it (``HandlerContext``, a narrow view of the
session); it raises ``RwtError`` to refuse the op, which the session turns
into a ``status`` frame.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from ... import ops
from . import actions, control, encodings, services, topics
from .context import HandlerContext

__all__ = ["HANDLERS", "Handler", "HandlerContext"]

Handler = Callable[[HandlerContext, Any, float], None]
"""``handler(context, op, now)``: the table's value type; ``_entry`` checks each pair."""

T = TypeVar("T")


def _entry(
    op_type: type[T], handler: Callable[[HandlerContext, T, float], None]
) -> tuple[type, Handler]:
    """One row of the table: the type checker makes sure ``handler`` takes ``op_type``."""
    return (op_type, handler)


HANDLERS: dict[type, Handler] = dict(
    [
        _entry(ops.Advertise, topics.advertise),
        _entry(ops.Unadvertise, topics.unadvertise),
        _entry(ops.Publish, topics.publish),
        (ops.PublishFrame, topics.publish),  # generated twin of Publish (ops.wire)
        _entry(ops.Subscribe, topics.subscribe),
        _entry(ops.Unsubscribe, topics.unsubscribe),
        _entry(ops.SetLevel, control.set_level),
        _entry(ops.Status, control.status),
        _entry(ops.Auth, control.auth),
        _entry(ops.AdvertiseService, services.advertise_service),
        _entry(ops.UnadvertiseService, services.unadvertise_service),
        _entry(ops.CallService, services.call_service),
        _entry(ops.ServiceResponse, services.service_response),
        _entry(ops.AdvertiseAction, actions.advertise_action),
        _entry(ops.UnadvertiseAction, actions.unadvertise_action),
        _entry(ops.SendActionGoal, actions.send_action_goal),
        _entry(ops.CancelActionGoal, actions.cancel_action_goal),
        _entry(ops.ActionFeedback, actions.action_feedback),
        _entry(ops.ActionResult, actions.action_result),
        _entry(ops.Fragment, encodings.fragment),
        _entry(ops.Png, encodings.png),
    ]
)
