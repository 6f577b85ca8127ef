"""One pydantic model per rosbridge op: each op's one definition.

``OP_MODELS`` maps each wire name to its model (both spec editions). The
models validate what a peer sends (``codecs.json.parse_object``) and are what rwt
sends (``ServiceResponse(...)``, encoded by ``codecs.json.op_object``), in the
server and the client alike; ``ops.wire`` generates the msgspec decoder of the
publish hot path from them.
"""

from __future__ import annotations

from .actions import (
    ActionFeedback,
    ActionResult,
    AdvertiseAction,
    CancelActionGoal,
    SendActionGoal,
    UnadvertiseAction,
)
from .base import OpModel
from .control import Auth, Fragment, Png, SetLevel, Status
from .services import AdvertiseService, CallService, ServiceResponse, UnadvertiseService
from .topics import Advertise, Publish, Subscribe, Unadvertise, Unsubscribe
from .wire import PublishFrame, PublishView, wire_struct

__all__ = [
    "OP_MODELS",
    "ActionFeedback",
    "ActionResult",
    "Advertise",
    "AdvertiseAction",
    "AdvertiseService",
    "Auth",
    "CallService",
    "CancelActionGoal",
    "Fragment",
    "OpModel",
    "Png",
    "Publish",
    "PublishFrame",
    "PublishView",
    "SendActionGoal",
    "ServiceResponse",
    "SetLevel",
    "Status",
    "Subscribe",
    "Unadvertise",
    "UnadvertiseAction",
    "UnadvertiseService",
    "Unsubscribe",
    "wire_struct",
]

_MODELS: tuple[type[OpModel], ...] = (
    Advertise,
    Unadvertise,
    Publish,
    Subscribe,
    Unsubscribe,
    AdvertiseService,
    UnadvertiseService,
    CallService,
    ServiceResponse,
    AdvertiseAction,
    UnadvertiseAction,
    SendActionGoal,
    CancelActionGoal,
    ActionFeedback,
    ActionResult,
    Fragment,
    Png,
    SetLevel,
    Status,
    Auth,
)

OP_MODELS: dict[str, type[OpModel]] = {model.model_fields["op"].default: model for model in _MODELS}
"""Wire name of each op -> its model class."""
