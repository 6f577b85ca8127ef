"""The interface between the protocol session and whatever graph backs it.

``rwt_protocol`` cannot import the graph (layering, STYLE.md), so the session
talks to a ``GraphPort`` and the graph calls back into a ``TopicSink``. Both are
structural ``typing.Protocol`` types; ``rwt_graph.Graph`` implements the port.
All calls are synchronous and never block: the graph is in-memory.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from enum import IntEnum
from typing import Protocol

__all__ = [
    "ActionProvider",
    "ClientId",
    "GoalDone",
    "GoalFeedback",
    "GoalHandle",
    "GoalStatus",
    "GraphPort",
    "MessageEvent",
    "Pending",
    "ServicePort",
    "ServiceProvider",
    "ServiceReply",
    "TopicSink",
]

ClientId = str
"""Opaque identity of one connection (or in-process participant) in the graph."""


class MessageEvent:
    """One message published on a topic, shared by every subscriber.

    Subscribers encode through ``encoded`` so that a message published to N
    subscribers is serialized once per distinct encoding (issue 4 "encode once").

    Attributes:
        topic: resolved topic name (``/chatter``).
        type_name: canonical message type (``std_msgs/msg/String``).
        msg: the message in the graph's internal form (a dict; ``bytes`` for
            ``uint8[]``), never mutated after publication.
        now: monotonic seconds when it was published.
    """

    __slots__ = ("_cache", "msg", "now", "topic", "type_name")

    def __init__(self, topic: str, type_name: str, msg: dict[str, object], now: float) -> None:
        self.topic = topic
        self.type_name = type_name
        self.msg = msg
        self.now = now
        self._cache: dict[Hashable, bytes] = {}

    def encoded(self, key: Hashable, make: Callable[[], bytes]) -> bytes:
        """Return the cached encoding for ``key``, making it on first use."""
        frame = self._cache.get(key)
        if frame is None:
            frame = self._cache[key] = make()
        return frame

    @property
    def encodings_made(self) -> int:
        """How many distinct encodings were made so far (for tests and benchmarks)."""
        return len(self._cache)


class TopicSink(Protocol):
    """Receives the messages of one topic for one subscriber."""

    def on_message(self, event: MessageEvent) -> None:
        """Take one message; must not block or raise."""


class GoalStatus(IntEnum):
    """``action_msgs/msg/GoalStatus`` codes (spec 3.3.15, REF §6.3)."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6


ServiceReply = Callable[[bool, object], None]
"""Called once with ``(result, values)``: values is a response dict on success,
an error text on failure (PROTOCOL-DECISIONS D28)."""

GoalFeedback = Callable[[dict[str, object]], None]
"""Called with each feedback message of a goal."""

GoalDone = Callable[[GoalStatus, bool, object], None]
"""Called once with ``(status, result, values)`` when a goal ends (D4, D18)."""


class Pending(Protocol):
    """A call or goal in flight, as its caller holds it."""

    def forget(self) -> None:
        """Stop waiting: no reply will be delivered (timeout, caller gone)."""


class GoalHandle(Pending, Protocol):
    """A goal in flight, as its caller holds it."""

    def request_cancel(self) -> None:
        """Ask the action server to cancel the goal (spec 3.3.13)."""


class ServiceProvider(Protocol):
    """The session side of a client-advertised service (spec 3.3.6, REF §2.7)."""

    def on_service_request(self, request_id: str, service: str, args: dict[str, object]) -> None:
        """Forward a request; ``service`` is spelled as the provider advertised it (D26)."""

    def on_service_lost(self, service: str, reason: str) -> None:
        """The service was taken away from this provider (replaced, D15)."""


class ActionProvider(Protocol):
    """The session side of a client-advertised action (spec 3.3.10, REF §2.15-2.16)."""

    def on_action_goal(
        self, goal_id: str, action: str, action_type: str, args: dict[str, object]
    ) -> None:
        """Forward a goal; names spelled as the provider advertised them (D26)."""

    def on_action_cancel(self, goal_id: str, action: str) -> None:
        """Forward a cancel request for ``goal_id``."""

    def on_action_lost(self, action: str, reason: str) -> None:
        """The action was taken away from this provider (replaced, D15)."""


class ServicePort(Protocol):
    """What a server session needs from the graph for services and actions."""

    def advertise_service(
        self, client: ClientId, service: str, type_name: str, provider: ServiceProvider
    ) -> str:
        """Offer a service (newest advertiser wins, D15); return its canonical type."""

    def unadvertise_service(self, client: ClientId, service: str) -> None:
        """Withdraw a service ``client`` advertised; its pending calls fail (D15)."""

    def call_service(
        self,
        client: ClientId,
        service: str,
        args: object,
        reply: ServiceReply,
        *,
        type_name: str | None,
        path: str,
    ) -> Pending:
        """Start a call; ``reply`` may run before this returns (in-process services)."""

    def service_response(
        self,
        client: ClientId,
        service: str,
        request_id: str,
        result: bool,
        values: object,
        *,
        path: str,
    ) -> None:
        """Answer a request forwarded to ``client`` (only the advertiser may, D15)."""

    def advertise_action(
        self, client: ClientId, action: str, type_name: str, provider: ActionProvider
    ) -> str:
        """Offer an action (newest advertiser wins); return its canonical type."""

    def unadvertise_action(self, client: ClientId, action: str) -> None:
        """Withdraw an action ``client`` advertised; its goals abort."""

    def send_action_goal(
        self,
        client: ClientId,
        action: str,
        action_type: str,
        args: object,
        done: GoalDone,
        feedback: GoalFeedback | None,
        *,
        path: str,
    ) -> GoalHandle:
        """Start a goal; ``done`` may run before this returns."""

    def action_feedback(
        self, client: ClientId, action: str, goal_id: str, values: object, *, path: str
    ) -> None:
        """Feedback from the advertiser of ``action`` for ``goal_id``."""

    def action_result(
        self,
        client: ClientId,
        action: str,
        goal_id: str,
        status: int | None,
        result: bool,
        values: object,
        *,
        path: str,
    ) -> None:
        """The end of ``goal_id`` from the advertiser of ``action`` (D18)."""


class GraphPort(ServicePort, Protocol):
    """What a server session needs from the graph: topics (spec 3.3.1-3.3.5) and services.

    Every method raises ``rwt_protocol.errors.GraphError`` (or a subclass) for a
    request the graph refuses; the session reports it as a ``status``.
    """

    def advertise(self, client: ClientId, topic: str, type_name: str, *, latch: bool) -> str:
        """Register ``client`` as a publisher; return the topic's canonical type."""

    def unadvertise(self, client: ClientId, topic: str) -> None:
        """Remove ``client`` as a publisher of ``topic``."""

    def publish(
        self, client: ClientId, topic: str, msg: object, *, latch: bool, path: str
    ) -> tuple[str, ...]:
        """Validate and publish ``msg``; return the paths of fields filled with defaults.

        ``path`` is the JSON path of ``msg`` in the op, for error texts (``$.msg``).
        """

    def subscribe(
        self, client: ClientId, topic: str, type_name: str | None, sink: TopicSink
    ) -> str:
        """Attach ``sink`` for ``client`` (replacing an earlier one); return the canonical type."""

    def unsubscribe(self, client: ClientId, topic: str) -> None:
        """Detach ``client``'s sink from ``topic``."""

    def release(self, client: ClientId) -> None:
        """Drop everything ``client`` holds (it disconnected)."""
