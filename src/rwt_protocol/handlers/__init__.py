"""The dispatcher table: op model -> handler (a table, not an if/elif chain).

A handler is ``handler(session, op, now) -> None``; it raises ``RwtError`` to
refuse the op, which the session turns into a ``status`` frame.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from .. import ops
from . import actions, control, encodings, services, topics

if TYPE_CHECKING:
    from ..session import Session

__all__ = ["HANDLERS", "Handler"]

Handler = Callable[["Session", Any, float], None]

HANDLERS: dict[type, Handler] = {
    ops.Advertise: topics.advertise,
    ops.Unadvertise: topics.unadvertise,
    ops.Publish: topics.publish,
    ops.PublishFrame: topics.publish,
    ops.Subscribe: topics.subscribe,
    ops.Unsubscribe: topics.unsubscribe,
    ops.SetLevel: control.set_level,
    ops.Status: control.status,
    ops.Auth: control.auth,
    ops.AdvertiseService: services.advertise_service,
    ops.UnadvertiseService: services.unadvertise_service,
    ops.CallService: services.call_service,
    ops.ServiceResponse: services.service_response,
    ops.AdvertiseAction: actions.advertise_action,
    ops.UnadvertiseAction: actions.unadvertise_action,
    ops.SendActionGoal: actions.send_action_goal,
    ops.CancelActionGoal: actions.cancel_action_goal,
    ops.ActionFeedback: actions.action_feedback,
    ops.ActionResult: actions.action_result,
    ops.Fragment: encodings.fragment,
    ops.Png: encodings.png,
}
