"""Access rules: which topics, services, parameters and actions a client may use.

rosbridge's ``topics_glob``, ``services_glob`` and ``params_glob`` parameters
(REF §1.2), plus ``actions_glob``, which rosbridge has in code but never wires:
each is a list of ``fnmatch`` patterns matched against resolved names
(``/chatter``); an empty list means no filtering. The session checks every op
against the policy before dispatch, by op family and name, so every handler is
covered without knowing about it. Unlike the reference, which drops a denied op
with only a log line (a denied ``call_service`` then waits forever), a denied op
gets an error ``status`` (D1) and its natural failure reply (D4).

As in rosbridge, the built-in ``/rosapi/*`` services stay reachable when service
patterns are set; rosapi itself lists only what the policy allows
(``AccessPolicy.filter``), and its parameter services check the parameter name
against the parameter patterns here.
"""

from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING

from ..errors import RemoteProtocolError
from ..names import resolve_name
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

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping, Sequence

__all__ = ["AccessDeniedError", "AccessPolicy", "Family", "parse_glob_list"]

ROSAPI_PREFIX = "/rosapi/"
_PARAM_SERVICES = frozenset(
    f"{ROSAPI_PREFIX}{name}"
    for name in ("get_param", "set_param", "has_param", "delete_param", "search_param")
)


class Family(StrEnum):
    """The kinds of names an access rule applies to (one ``--*-glob`` option each)."""

    TOPICS = "topics"
    SERVICES = "services"
    PARAMS = "params"
    ACTIONS = "actions"


class AccessDeniedError(RemoteProtocolError):
    """An op names something the server's access rules do not allow (error status, D1)."""


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


def parse_glob_list(text: str) -> tuple[str, ...]:
    """Parse a rosbridge glob parameter into patterns.

    Args:
        text: rosbridge's list form ``"[/a/*, '/b']"``, or a plain comma-separated
            list ``"/a/*,/b"``; blanks and quotes around items are ignored.

    Returns:
        The patterns; empty (no filtering) for ``""`` or ``"[]"``, as in rosbridge.
    """
    text = text.strip()
    if text.startswith("[") and text.endswith("]"):
        text = text[1:-1]
    items = (item.strip().strip("'\"").strip() for item in text.split(","))
    return tuple(item for item in items if item)


def _compile(patterns: Iterable[str], *, absolute: bool) -> re.Pattern[str] | None:
    """One regular expression matching any pattern; None when there are none (allow all).

    With ``absolute``, a pattern written as a relative name (``chatter``) is made
    absolute (``/chatter``), since it is matched against resolved names.
    """
    normalized = [
        f"/{p}" if absolute and not p.startswith(("/", "*", "?", "[")) else p for p in patterns
    ]
    if not normalized:
        return None
    return re.compile("|".join(f"(?:{fnmatch.translate(p)})" for p in normalized))


@dataclass(frozen=True)
class AccessPolicy:
    """The access rules of a server (``--topics-glob`` and friends).

    Attributes:
        topics: fnmatch patterns of allowed topics; empty allows every topic.
        services: patterns of allowed services (``/rosapi/*`` is always allowed).
        params: patterns of allowed parameter names.
        actions: patterns of allowed actions.
    """

    topics: Sequence[str] = ()
    services: Sequence[str] = ()
    params: Sequence[str] = ()
    actions: Sequence[str] = ()
    _matchers: dict[Family, re.Pattern[str] | None] = field(
        init=False, repr=False, compare=False, default_factory=dict
    )

    def __post_init__(self) -> None:
        for family in Family:
            absolute = family is not Family.PARAMS
            self._matchers[family] = _compile(getattr(self, family.value), absolute=absolute)

    @property
    def restricted(self) -> bool:
        """Whether any family is filtered at all."""
        return any(matcher is not None for matcher in self._matchers.values())

    def allows(self, family: Family, name: str) -> bool:
        """Whether a client may use ``name``.

        Topic, service and action names are resolved first (``chatter`` is
        ``/chatter``, D26); parameter names are matched as written.
        """
        return self._allows(family, name, calling=True)

    def _allows(self, family: Family, name: str, *, calling: bool) -> bool:
        matcher = self._matchers[family]
        if matcher is None:
            return True
        resolved = name if family is Family.PARAMS else resolve_name(name)
        if calling and family is Family.SERVICES and resolved.startswith(ROSAPI_PREFIX):
            return True  # calling rosapi, never advertising over it
        return matcher.fullmatch(resolved) is not None

    def filter(self, family: Family, names: Iterable[str]) -> list[str]:
        """The names a client may see, in their order (for rosapi's listings)."""
        return [name for name in names if self.allows(family, name)]

    def check(self, op: OpModel | PublishView) -> None:
        """Refuse an op that names something not allowed; do nothing otherwise.

        Raises:
            AccessDeniedError: the op's topic, service, action or (for rosapi's
                parameter services) parameter name is not allowed.
        """
        entry = _OP_FAMILIES.get(type(op))
        if entry is None:
            return
        family, attribute = entry
        name: str = getattr(op, attribute)
        if not self._allows(family, name, calling=isinstance(op, CallService)):
            raise AccessDeniedError(f"{family.value[:-1]} {name} is not allowed on this server")
        if isinstance(op, CallService) and resolve_name(op.service) in _PARAM_SERVICES:
            param = _param_name(op.args)
            if param is not None and not self.allows(Family.PARAMS, param):
                raise AccessDeniedError(f"parameter {param} is not allowed on this server")


def _param_name(args: object) -> str | None:
    """The ``name`` argument of a rosapi parameter call, keyword or first positional (D25)."""
    if isinstance(args, dict):
        value = args.get("name")
    elif isinstance(args, list) and args:
        value = args[0]
    else:
        return None
    return value if isinstance(value, str) else None
