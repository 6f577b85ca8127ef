"""Action ops (spec 3.3.10-3.3.15, ROS 2 edition)."""

from __future__ import annotations

from typing import Any, Literal

from .base import Compression, CompressionField, FragmentSize, GraphName, Int64, MessageId, OpModel

__all__ = [
    "ActionFeedback",
    "ActionResult",
    "AdvertiseAction",
    "CancelActionGoal",
    "SendActionGoal",
    "UnadvertiseAction",
]


class AdvertiseAction(OpModel):
    """Offer ``action`` of ``type``; goals arrive as ``send_action_goal`` (spec 3.3.10)."""

    op: Literal["advertise_action"] = "advertise_action"
    action: GraphName
    type: str
    id: MessageId | None = None


class UnadvertiseAction(OpModel):
    """Withdraw an action this client advertised (spec 3.3.11)."""

    op: Literal["unadvertise_action"] = "unadvertise_action"
    action: GraphName
    id: MessageId | None = None


class SendActionGoal(OpModel):
    """Send a goal; in the other direction, a goal for an advertiser (spec 3.3.12).

    ``feedback`` asks for ``action_feedback`` messages (default false, D18).
    """

    op: Literal["send_action_goal"] = "send_action_goal"
    action: GraphName
    action_type: str
    args: Any = None
    id: MessageId | None = None
    feedback: bool = False
    fragment_size: FragmentSize | None = None
    compression: CompressionField = Compression.NONE


class CancelActionGoal(OpModel):
    """Cancel the goal with ``id`` (spec 3.3.13)."""

    op: Literal["cancel_action_goal"] = "cancel_action_goal"
    action: GraphName
    id: MessageId


class ActionFeedback(OpModel):
    """Feedback for the goal ``id`` (spec 3.3.14).

    ``id`` is absent only in what rwt sends for a goal sent without one; an
    advertiser's feedback must name its goal (its handler refuses it otherwise).
    """

    op: Literal["action_feedback"] = "action_feedback"
    action: GraphName
    id: MessageId | None = None
    values: Any = None


class ActionResult(OpModel):
    """The result of the goal ``id`` (spec 3.3.15).

    ``status`` is an ``action_msgs/GoalStatus`` code; an advertiser may omit it
    (4 when ``result`` is true, 6 otherwise; D18). ``id`` is absent only as
    in ``ActionFeedback``.
    """

    op: Literal["action_result"] = "action_result"
    action: GraphName
    id: MessageId | None = None
    result: bool
    values: Any = None
    status: Int64 | None = None
