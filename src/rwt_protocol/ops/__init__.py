"""One pydantic model per rosbridge op, and the union of them all.

``Op`` is a discriminated union on ``op`` covering both spec editions;
``OP_MODELS`` maps each wire name to its model.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

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
from .topics import Advertise, Publish, PublishFrame, Subscribe, Unadvertise, Unsubscribe

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
    "Op",
    "OpModel",
    "Png",
    "Publish",
    "PublishFrame",
    "SendActionGoal",
    "ServiceResponse",
    "SetLevel",
    "Status",
    "Subscribe",
    "Unadvertise",
    "UnadvertiseAction",
    "UnadvertiseService",
    "Unsubscribe",
]

Op = Annotated[
    Advertise
    | Unadvertise
    | Publish
    | Subscribe
    | Unsubscribe
    | AdvertiseService
    | UnadvertiseService
    | CallService
    | ServiceResponse
    | AdvertiseAction
    | UnadvertiseAction
    | SendActionGoal
    | CancelActionGoal
    | ActionFeedback
    | ActionResult
    | Fragment
    | Png
    | SetLevel
    | Status
    | Auth,
    Field(discriminator="op"),
]
"""Any rosbridge op, discriminated by its ``op`` field."""

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
