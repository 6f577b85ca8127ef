"""The dispatcher table: op model -> handler (STYLE.md: a table, not an if/elif chain).

A handler is ``handler(session, op, now) -> None``; it raises ``RwtError`` to
refuse the op, which the session turns into a ``status`` frame.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from .. import ops
from . import control, encodings, pending, topics

if TYPE_CHECKING:
    from ..session import Session

__all__ = ["HANDLERS", "Handler"]

Handler = Callable[["Session", Any, float], None]

HANDLERS: dict[type[ops.OpModel], Handler] = {
    ops.Advertise: topics.advertise,
    ops.Unadvertise: topics.unadvertise,
    ops.Publish: topics.publish,
    ops.Subscribe: topics.subscribe,
    ops.Unsubscribe: topics.unsubscribe,
    ops.SetLevel: control.set_level,
    ops.Status: control.status,
    ops.Auth: control.auth,
    ops.CallService: pending.refuse_call_service,
    ops.SendActionGoal: pending.refuse_send_action_goal,
    ops.ServiceResponse: pending.refuse,
    ops.AdvertiseService: pending.refuse,
    ops.UnadvertiseService: pending.refuse,
    ops.AdvertiseAction: pending.refuse,
    ops.UnadvertiseAction: pending.refuse,
    ops.CancelActionGoal: pending.refuse,
    ops.ActionFeedback: pending.refuse,
    ops.ActionResult: pending.refuse,
    ops.Fragment: encodings.fragment,
    ops.Png: encodings.png,
}
