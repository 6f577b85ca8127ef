"""Access rules: which topics, services, parameters and actions a client may use.

rosbridge's ``topics_glob``, ``services_glob`` and ``params_glob`` parameters
(REF §1.2), plus ``actions_glob``, which rosbridge has in code but never wires:
each is a list of ``fnmatch`` patterns matched against resolved names
(``/chatter``); an empty list means no filtering.

rosbridge's split topic globs (REF §13.5, D50), ``topics_pub_glob`` for what a
client publishes (advertise, unadvertise, publish) and ``topics_sub_glob`` for
what it subscribes to: unset (None), each is ``topics_glob`` as it is; set, even
to an empty list, it is its own patterns plus ``topics_glob``'s, and an empty
result allows nothing. A listing shows a topic either one allows
(``TopicUse``: None). Every refusal names the glob that refused it
(``AccessPolicy.refusal``, ``AccessDeniedError.glob``).

Every refusal goes through the one access gate, ``gate`` (or, for a refusal a
protocol words itself, ``log_denied``), and its one log line
(``event=access_denied client=... op=... glob=... reason=...``, once per episode,
repeats counted): every protocol's session (``SessionBase.require_access``: Foxglove's
topics and parameters, the HTTP API's names), rosbridge's op check (which checks every
op before dispatch, by op family and name, ``rwt_protocol.server.op_access``, so every
handler is covered without knowing about it), the MCP tools' guard and WebRTC's video
tracks. Unlike the reference, which
drops a denied op with only a log line (a denied ``call_service`` then waits
forever), a denied op gets an error ``status`` (D1) and its natural failure reply
(D4).

As in rosbridge, the built-in ``/rosapi/*`` services stay reachable when service
patterns are set; rosapi itself lists only what the policy allows
(``AccessPolicy.filter``), and its parameter services check the parameter name
against the parameter patterns (``op_access``).
"""

from __future__ import annotations

import fnmatch
import logging
import re
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING

from ..errors import RemoteProtocolError
from ..names import resolve_name
from ..ratelog import EpisodeLog

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

__all__ = [
    "AccessDeniedError",
    "AccessPolicy",
    "Family",
    "TopicUse",
    "gate",
    "log_denied",
    "log_refused",
    "param_call_name",
    "parse_glob_list",
    "parse_split_glob",
]

logger = logging.getLogger("rwt.session")
_episodes = EpisodeLog(logger)  # a peer triggers these at will: one line per episode

ROSAPI_PREFIX = "/rosapi/"


class Family(StrEnum):
    """The kinds of names an access rule applies to (one ``--*-glob`` option each)."""

    TOPICS = "topics"
    SERVICES = "services"
    PARAMS = "params"
    ACTIONS = "actions"


class TopicUse(StrEnum):
    """What a client does with a topic: which split glob decides (REF §13.5, D50)."""

    PUBLISH = "pub"
    SUBSCRIBE = "sub"


class AccessDeniedError(RemoteProtocolError):
    """An op names something the server's access rules do not allow (error status, D1).

    Args:
        message: what the client is told (``topic /x is not allowed on this server``).
        glob: the rule that refused, as rosbridge names it (``topics_pub_glob``), for
            the server's log.
    """

    def __init__(self, message: str, glob: str = "") -> None:
        super().__init__(message)
        self.glob = glob


_NOTHING = re.compile(r"(?!)")
"""Matches no name: a set glob whose list is empty (``"[]"``, REF §13.5)."""


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


def parse_split_glob(text: str) -> tuple[str, ...] | None:
    """Parse ``--topics-pub-glob`` or ``--topics-sub-glob`` as rosbridge does (REF §13.5).

    Args:
        text: as for ``parse_glob_list``.

    Returns:
        None for ``""`` (unset: ``topics_glob`` decides); otherwise the patterns,
        empty for ``"[]"`` (which, with no ``topics_glob``, allows nothing).
    """
    if not text.strip():
        return None
    return parse_glob_list(text)


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
        topics_pub: ``--topics-pub-glob``: None (unset) leaves publishing to
            ``topics``; a tuple, even empty, is merged with ``topics`` (REF §13.5).
        topics_sub: ``--topics-sub-glob``, the same for subscribing.
    """

    topics: Sequence[str] = ()
    services: Sequence[str] = ()
    params: Sequence[str] = ()
    actions: Sequence[str] = ()
    topics_pub: Sequence[str] | None = None
    topics_sub: Sequence[str] | None = None
    _matchers: dict[Family, re.Pattern[str] | None] = field(
        init=False, repr=False, compare=False, default_factory=dict
    )
    _topic_matchers: dict[TopicUse, re.Pattern[str] | None] = field(
        init=False, repr=False, compare=False, default_factory=dict
    )

    def __post_init__(self) -> None:
        for family in Family:
            absolute = family is not Family.PARAMS
            self._matchers[family] = _compile(getattr(self, family.value), absolute=absolute)
        for use in TopicUse:
            own = self._own(use)
            if own is None:  # unset: topics_glob as it is
                self._topic_matchers[use] = self._matchers[Family.TOPICS]
            else:  # set: its own patterns plus topics_glob's; none at all match nothing
                merged = [*own, *self.topics]
                self._topic_matchers[use] = _compile(merged, absolute=True) or _NOTHING

    def _own(self, use: TopicUse) -> Sequence[str] | None:
        return self.topics_pub if use is TopicUse.PUBLISH else self.topics_sub

    def patterns(self, glob: str) -> tuple[str, ...]:
        """The patterns a rule named as ``refusal`` names it holds (``topics_pub_glob``).

        A set split glob holds its own patterns then ``topics_glob``'s (REF §13.5).
        """
        for use in TopicUse:
            own = self._own(use)
            if glob == f"topics_{use.value}_glob" and own is not None:
                return (*own, *self.topics)
        family = glob.removesuffix("_glob")
        return tuple(getattr(self, family)) if family in set(Family) else ()

    @property
    def restricted(self) -> bool:
        """Whether any family (or either use of topics) is filtered at all."""
        matchers = [*self._matchers.values(), *self._topic_matchers.values()]
        return any(matcher is not None for matcher in matchers)

    def allows(self, family: Family, name: str, use: TopicUse | None = None) -> bool:
        """Whether a client may use ``name``.

        Topic, service and action names are resolved first (``chatter`` is
        ``/chatter``, D26); parameter names are matched as written.

        Args:
            family: what ``name`` is.
            name: the name.
            use: for a topic, publishing or subscribing (the split globs, D50);
                None asks whether it may be listed: either use allows it.
        """
        return self.refusal(family, name, use) is None

    def refusal(
        self, family: Family, name: str, use: TopicUse | None = None, *, calling: bool = True
    ) -> str | None:
        """The glob refusing ``name``, as rosbridge names it (``topics_sub_glob``), or None.

        Args as for ``allows``, and ``calling``: the client calls ``name`` (a
        service), so ``/rosapi/*`` stays allowed; False for advertising it.
        """
        if family is Family.TOPICS:
            return self._topic_refusal(name, use)
        matcher = self._matchers[family]
        if matcher is None:
            return None
        resolved = name if family is Family.PARAMS else resolve_name(name)
        if calling and family is Family.SERVICES and resolved.startswith(ROSAPI_PREFIX):
            return None  # calling rosapi, never advertising over it
        return None if matcher.fullmatch(resolved) is not None else f"{family.value}_glob"

    def _topic_refusal(self, name: str, use: TopicUse | None) -> str | None:
        uses = (TopicUse.PUBLISH, TopicUse.SUBSCRIBE) if use is None else (use,)
        refused: list[str] = []
        for each in uses:
            matcher = self._topic_matchers[each]
            if matcher is None or matcher.fullmatch(resolve_name(name)) is not None:
                return None  # a listing shows what either use allows
            own = self._own(each)
            refused.append("topics_glob" if own is None else f"topics_{each.value}_glob")
        return "/".join(dict.fromkeys(refused))

    def filter(self, family: Family, names: Iterable[str]) -> list[str]:
        """The names a client may see, in their order (for rosapi's listings)."""
        return [name for name in names if self.allows(family, name)]


def gate(
    policy: AccessPolicy,
    family: Family,
    name: str,
    *,
    client: str,
    op: str,
    use: TopicUse | None = None,
    now: float,
) -> None:
    """The one access gate: refuse what ``policy`` denies, with the one log line.

    Args:
        policy: the server's access rules (``--topics-glob`` and friends).
        family: what ``name`` is (topic, service, action, parameter).
        name: the name the client asked for.
        client: who asked (a client id, ``webrtc:HOST:PORT``), for the log.
        op: what it asked for (``subscribe``, ``advertise``, ``video``, a tool's name).
        use: for a topic, publishing or subscribing (the split globs, D50); None
            checks it as a listing would.
        now: the caller's monotonic seconds (the core reads no clock), for the log.

    Raises:
        AccessDeniedError: ``name`` is outside the rules; its ``glob`` names the
            rule that refused (``topics_sub_glob``).
    """
    glob = policy.refusal(family, name, use)
    if glob is None:
        return
    denied = AccessDeniedError(f"{family.value[:-1]} {name} is not allowed on this server", glob)
    log_denied(denied, client=client, op=op, now=now)
    raise denied


def log_denied(denied: AccessDeniedError, *, client: str, op: str, now: float) -> None:
    """The access gate's one log line, for a refusal ``denied`` (``gate`` writes it too).

    ``event=access_denied client=... op=... glob=... reason=...``, once per episode
    of refusals, repeats counted (``ratelog.EpisodeLog``): a client repeating them
    cannot write the log at its own rate.
    """
    _episodes.log(
        logging.WARNING,
        "access_denied",
        "event=access_denied client=%s op=%s glob=%s reason=%r",
        client,
        op,
        denied.glob,
        denied.message,
        now=now,
    )


def log_refused(*, client: str, op: str, rule: str, reason: str, now: float) -> None:
    """The access log's line for a refusal by a rule that is not a glob (D53).

    ``event=access_denied client=... op=... rule=... reason=...``: read-only mode
    (``rule=--mcp-read-only``), a rate or size cap (``rule=TOOL_CALLS_PER_S``), in the
    same episodes as ``log_denied``'s lines, so an operator greps one event for every
    refusal and a client repeating them cannot write the log at its own rate.
    """
    _episodes.log(
        logging.WARNING,
        "access_denied",
        "event=access_denied client=%s op=%s rule=%s reason=%r",
        client,
        op,
        rule,
        reason,
        now=now,
    )


_PARAM_SERVICES = frozenset(
    f"{ROSAPI_PREFIX}{name}"
    for name in ("get_param", "set_param", "has_param", "delete_param", "search_param")
)
"""rosapi's parameter services: a call names its parameter (``param_call_name``)."""


def param_call_name(service: str, args: object) -> str | None:
    """The parameter a call of ``service`` names, if it is one of rosapi's parameter services.

    Its ``name`` argument, keyword or first positional (D25); None for any other
    service, or a call that names none. Every protocol that calls rosapi checks
    this name against ``--params-glob`` (REF §1.2).
    """
    if resolve_name(service) not in _PARAM_SERVICES:
        return None
    if isinstance(args, dict):
        value = args.get("name")
    elif isinstance(args, list) and args:
        value = args[0]
    else:
        return None
    return value if isinstance(value, str) else None
