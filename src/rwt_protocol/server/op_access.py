"""rosbridge's ops against the access rules: which name of which op each glob checks.

The rules themselves are every protocol's (``rwt_protocol.runtime.access``);
this is rosbridge's side of them: each op that names a topic, service or
action, the family and field its name is in, and for a topic which split glob
decides (REF §13.5, D50). rosapi's parameter services are checked against the
parameter patterns by their ``name`` argument (REF §1.2).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..ops import (
    Advertise,
    AdvertiseAction,
    AdvertiseService,
    CallService,
    CancelActionGoal,
    OpModel,
    Publish,
    PublishFrame,
    PublishView,
    SendActionGoal,
    Subscribe,
    Unadvertise,
    UnadvertiseAction,
    UnadvertiseService,
    Unsubscribe,
)
from ..runtime.access import AccessDeniedError, Family, TopicUse, param_call_name

if TYPE_CHECKING:
    from collections.abc import Mapping

    from ..runtime.access import AccessPolicy

__all__ = ["check_op"]

_OP_FAMILIES: Mapping[type, tuple[Family, str]] = {
    Advertise: (Family.TOPICS, "topic"),
    Unadvertise: (Family.TOPICS, "topic"),
    Publish: (Family.TOPICS, "topic"),
    PublishFrame: (Family.TOPICS, "topic"),
    Subscribe: (Family.TOPICS, "topic"),
    Unsubscribe: (Family.TOPICS, "topic"),
    CallService: (Family.SERVICES, "service"),
    AdvertiseService: (Family.SERVICES, "service"),
    UnadvertiseService: (Family.SERVICES, "service"),
    SendActionGoal: (Family.ACTIONS, "action"),
    CancelActionGoal: (Family.ACTIONS, "action"),
    AdvertiseAction: (Family.ACTIONS, "action"),
    UnadvertiseAction: (Family.ACTIONS, "action"),
}
"""Op model -> (family, name of the field holding the checked name)."""

_TOPIC_USES: Mapping[type, TopicUse] = {
    Advertise: TopicUse.PUBLISH,
    Unadvertise: TopicUse.PUBLISH,
    Publish: TopicUse.PUBLISH,
    PublishFrame: TopicUse.PUBLISH,
    Subscribe: TopicUse.SUBSCRIBE,
    Unsubscribe: TopicUse.SUBSCRIBE,
}
"""Topic op model -> the split glob that decides it (REF §13.5)."""


def check_op(policy: AccessPolicy, op: OpModel | PublishView) -> None:
    """Refuse an op that names something ``policy`` does not allow; do nothing otherwise.

    Raises:
        AccessDeniedError: the op's topic, service, action or (for rosapi's
            parameter services) parameter name is not allowed.
    """
    entry = _OP_FAMILIES.get(type(op))
    if entry is None:
        return
    family, attribute = entry
    name: str = getattr(op, attribute)
    use = _TOPIC_USES.get(type(op))
    glob = policy.refusal(family, name, use, calling=isinstance(op, CallService))
    if glob is not None:
        text = f"{family.value[:-1]} {name} is not allowed on this server"
        raise AccessDeniedError(text, glob)
    if isinstance(op, CallService):
        param = param_call_name(op.service, op.args)
        if param is not None and not policy.allows(Family.PARAMS, param):
            text = f"parameter {param} is not allowed on this server"
            raise AccessDeniedError(text, "params_glob")
