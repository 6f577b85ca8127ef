"""Quality of service: the policies of protocol 2.1.0's ``qos`` object, as the graph keeps them.

Protocol 2.1.0 (rosbridge_suite 2.7.0, 3.3.0, 4.2.0; docs/reference-behaviour.md §13.2)
adds an optional ``qos`` object to ``advertise``, ``publish`` and ``subscribe`` with
ROS 2's policies: ``history``, ``depth``, ``reliability``, ``durability``,
``deadline`` and ``lifespan``. The op models read the wire form
(``rwt_protocol.ops.qos``); this module holds what they become, ``QosProfile``, in
the graph's terms (policies as enums, durations in seconds), and the rules every
front end, the graph and the links share (D62-D65 of docs/decisions.md):

- ``QosProfile()`` is the system default, ROS 2's default profile
  (``rmw_qos_profile_default``): keep last 10, reliable, volatile, no deadline, no
  lifespan (D62). A ``qos`` of ``{}`` means it; a field left out takes its value.
- ``incompatibilities`` tells why a subscription cannot be matched with a
  publisher, by ROS 2's request-versus-offer rules (D64).
- ``for_subscription`` and ``for_publisher`` resolve ``best_available`` as rmw does.

No I/O and no clock here: durations are plain seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import StrEnum

__all__ = [
    "DEFAULT_DEPTH",
    "MAX_DEPTH",
    "Durability",
    "History",
    "QosProfile",
    "Reliability",
    "format_seconds",
    "incompatibilities",
]

DEFAULT_DEPTH = 10
"""History depth of the system default profile (``rmw_qos_profile_default``), and of a
``keep_last`` depth of 0 (``RMW_QOS_POLICY_DEPTH_SYSTEM_DEFAULT``; D62)."""

MAX_DEPTH = 10_000
"""The deepest history the server keeps for one topic or subscriber (docs/limits.md).

A deeper ``depth`` (or ``keep_all``) is capped here with a warning status; what a
store or a queue holds is also bounded by bytes (D63)."""


class History(StrEnum):
    """The ``history`` policy (spec 4.2.1 of protocol 2.1.0)."""

    KEEP_LAST = "keep_last"
    KEEP_ALL = "keep_all"


class Reliability(StrEnum):
    """The ``reliability`` policy (spec 4.2.1 of protocol 2.1.0)."""

    RELIABLE = "reliable"
    BEST_EFFORT = "best_effort"
    BEST_AVAILABLE = "best_available"


class Durability(StrEnum):
    """The ``durability`` policy (spec 4.2.1 of protocol 2.1.0)."""

    TRANSIENT_LOCAL = "transient_local"
    VOLATILE = "volatile"
    BEST_AVAILABLE = "best_available"


def format_seconds(seconds: float) -> str:
    """A duration for a status text: ``0.2 s``, ``infinite``."""
    return "infinite" if math.isinf(seconds) else f"{seconds:g} s"


@dataclass(frozen=True, slots=True)
class QosProfile:
    """One QoS profile, every policy set (a policy the client left out has its default).

    The defaults are the system default profile (D62). Durations are seconds;
    ``math.inf`` is ``infinite`` (no deadline, no lifespan), and 0 from the wire is
    read as that too (``RMW_DURATION_UNSPECIFIED``, D62).

    Attributes:
        history: keep the last ``depth`` messages, or all (within the server's
            bounds, ``MAX_DEPTH`` and bytes; D63).
        depth: messages kept with ``keep_last``, at least 1.
        reliability: ``reliable``, ``best_effort``, or ``best_available`` (resolved
            against the topic by ``for_subscription`` and ``for_publisher``).
        durability: ``transient_local`` (late subscribers get the kept messages),
            ``volatile``, or ``best_available``.
        deadline_s: the longest gap between two messages, seconds (inf: none).
        deadline_best_available: the deadline is ``best_available`` (resolved as
            ``reliability`` is); ``deadline_s`` is then inf.
        lifespan_s: how long a message may still be delivered after it was
            published, seconds (inf: for ever).
    """

    history: History = History.KEEP_LAST
    depth: int = DEFAULT_DEPTH
    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    deadline_s: float = math.inf
    deadline_best_available: bool = False
    lifespan_s: float = math.inf

    @property
    def keep(self) -> int:
        """Messages this profile keeps: ``depth``, or ``MAX_DEPTH`` for ``keep_all`` (D63)."""
        if self.history is History.KEEP_ALL:
            return MAX_DEPTH
        return min(self.depth, MAX_DEPTH)

    @property
    def capped(self) -> bool:
        """Whether ``keep`` is less than the client asked (a depth over ``MAX_DEPTH``)."""
        return self.history is History.KEEP_LAST and self.depth > MAX_DEPTH

    @property
    def transient_local(self) -> bool:
        """Whether late subscribers get the kept messages (``durability``)."""
        return self.durability is Durability.TRANSIENT_LOCAL

    @property
    def best_effort(self) -> bool:
        """Whether the server may drop messages first under pressure (``reliability``, D64)."""
        return self.reliability is Reliability.BEST_EFFORT

    def for_publisher(self) -> QosProfile:
        """The profile with ``best_available`` resolved for a publisher.

        As rmw does: reliable, transient local, no deadline (ROS 2's "best
        available" offers the most a subscription may ask).
        """
        profile = self
        if profile.reliability is Reliability.BEST_AVAILABLE:
            profile = replace(profile, reliability=Reliability.RELIABLE)
        if profile.durability is Durability.BEST_AVAILABLE:
            profile = replace(profile, durability=Durability.TRANSIENT_LOCAL)
        if profile.deadline_best_available:
            profile = replace(profile, deadline_best_available=False, deadline_s=math.inf)
        return profile

    def for_subscription(self, offered: QosProfile | None) -> QosProfile:
        """The profile with ``best_available`` resolved against the topic's ``offered`` QoS.

        As rmw does at a subscription's creation: reliable unless the offer is
        best effort, transient local if the offer is, the offer's deadline. With
        no offer (D62's adaptive default): reliable, transient local, no deadline,
        which matches any publisher.
        """
        profile = self
        if profile.reliability is Reliability.BEST_AVAILABLE:
            weak = offered is not None and offered.reliability is Reliability.BEST_EFFORT
            reliability = Reliability.BEST_EFFORT if weak else Reliability.RELIABLE
            profile = replace(profile, reliability=reliability)
        if profile.durability is Durability.BEST_AVAILABLE:
            durable = offered is None or offered.transient_local
            durability = Durability.TRANSIENT_LOCAL if durable else Durability.VOLATILE
            profile = replace(profile, durability=durability)
        if profile.deadline_best_available:
            deadline = math.inf if offered is None else offered.deadline_s
            profile = replace(profile, deadline_best_available=False, deadline_s=deadline)
        return profile

    def describe(self) -> str:
        """The profile in one line for a status: ``keep_last 5, reliable, transient_local``..."""
        history = "keep_all" if self.history is History.KEEP_ALL else f"keep_last {self.depth}"
        parts = [history, self.reliability.value, self.durability.value]
        if self.deadline_best_available:
            parts.append("deadline best_available")
        elif not math.isinf(self.deadline_s):
            parts.append(f"deadline {format_seconds(self.deadline_s)}")
        if not math.isinf(self.lifespan_s):
            parts.append(f"lifespan {format_seconds(self.lifespan_s)}")
        return ", ".join(parts)

    def to_json(self) -> dict[str, object]:
        """The profile as a ``qos`` object on the wire (every policy given)."""
        wire: dict[str, object] = {
            "history": self.history.value,
            "depth": self.depth,
            "reliability": self.reliability.value,
            "durability": self.durability.value,
            "deadline": "best_available"
            if self.deadline_best_available
            else _duration_json(self.deadline_s),
            "lifespan": _duration_json(self.lifespan_s),
        }
        return wire


def _duration_json(seconds: float) -> object:
    return "infinite" if math.isinf(seconds) else seconds


def incompatibilities(offered: QosProfile, requested: QosProfile) -> list[str]:
    """Why a subscription asking ``requested`` cannot match a publisher offering ``offered``.

    ROS 2's rules (an offer must be at least what is requested): a reliable
    subscription needs a reliable publisher, a transient-local one a
    transient-local publisher, a deadline no shorter than the publisher's
    (D64). Both profiles resolved (no ``best_available``).

    Returns:
        One reason per policy that does not match, empty when they match.
    """
    reasons = []
    if (
        requested.reliability is Reliability.RELIABLE
        and offered.reliability is Reliability.BEST_EFFORT
    ):
        reasons.append("reliability: reliable asked of a best_effort publisher")
    if requested.transient_local and offered.durability is Durability.VOLATILE:
        reasons.append("durability: transient_local asked of a volatile publisher")
    if offered.deadline_s > requested.deadline_s:
        reasons.append(
            f"deadline: {format_seconds(requested.deadline_s)} asked of a publisher"
            f" offering {format_seconds(offered.deadline_s)}"
        )
    return reasons
