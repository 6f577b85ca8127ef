"""What one connection holds in the graph, kept in one object with the methods that change it.

A session's subscriptions, advertisements, offered services and actions, goals
and counts of calls and goals waiting for their reply live here, not as loose
attributes of ``Session``: handlers read them through read-only views and
change them only through these methods, so every change has one name (and
``IdleWatch`` and the caps count the same things).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from collections.abc import Mapping, Set

    from ..ports import GoalHandle
    from .subscriptions import TopicSubscription

__all__ = ["Holdings", "OfferKind"]

OfferKind = Literal["service", "action"]
OpId = str | int | None


class Holdings:
    """One connection's holdings; names are resolved (``names.resolve_name``) by the caller."""

    __slots__ = (
        "_advertisements",
        "_goals",
        "_offers",
        "_pending_goals",
        "_subscriptions",
    )

    def __init__(self) -> None:
        self._subscriptions: dict[str, TopicSubscription] = {}
        self._advertisements: dict[str, set[OpId]] = {}
        self._offers: set[tuple[OfferKind, str]] = set()
        self._goals: dict[OpId, GoalHandle] = {}
        self._pending_goals = 0

    # ---- reading ----------------------------------------------------------------

    @property
    def subscriptions(self) -> Mapping[str, TopicSubscription]:
        """The subscription of each subscribed topic (its requests merged, D11)."""
        return self._subscriptions

    @property
    def advertisements(self) -> Mapping[str, Set[OpId]]:
        """The ``advertise`` ids held on each advertised topic."""
        return self._advertisements

    @property
    def offers(self) -> Set[tuple[OfferKind, str]]:
        """``("service" | "action", name)`` of each service and action offered."""
        return self._offers

    @property
    def goals(self) -> Mapping[OpId, GoalHandle]:
        """This connection's goals in progress, by their op id."""
        return self._goals

    @property
    def pending_goals(self) -> int:
        """``send_action_goal`` ops waiting for their result (counted by ``goal_started``)."""
        return self._pending_goals

    def offered(self) -> int:
        """Topics, services and actions advertised, together (one cap for all)."""
        return len(self._advertisements) + len(self._offers)

    def holds_anything(self) -> bool:
        """Whether anything is held that the peer waits on or serves (``IdleWatch``)."""
        return bool(
            self._subscriptions
            or self._advertisements
            or self._offers
            or self._goals
            or self._pending_goals
        )

    # ---- changing -----------------------------------------------------------------

    def add_subscription(self, topic: str, subscription: TopicSubscription) -> None:
        """Hold ``subscription`` as the one of ``topic``."""
        self._subscriptions[topic] = subscription

    def drop_subscription(self, topic: str) -> None:
        """Forget the subscription of ``topic`` (the caller closed it)."""
        del self._subscriptions[topic]

    def add_advertisement(self, topic: str, op_id: OpId) -> None:
        """Hold ``op_id`` as one of the advertisements of ``topic``."""
        self._advertisements.setdefault(topic, set()).add(op_id)

    def drop_advertisement(self, topic: str, op_id: OpId) -> bool:
        """Drop one advertise id (or all, for None) of ``topic``.

        Returns:
            Whether none is left, so that the topic is no longer advertised.

        Raises:
            KeyError: ``topic`` is not advertised.
        """
        ids = self._advertisements[topic]
        if op_id is None:
            ids.clear()
        else:
            ids.discard(op_id)
        if ids:
            return False
        del self._advertisements[topic]
        return True

    def add_offer(self, kind: OfferKind, name: str) -> None:
        """Hold an offered service or action."""
        self._offers.add((kind, name))

    def drop_offer(self, kind: OfferKind, name: str) -> None:
        """Forget an offered service or action (withdrawn, or taken away, D15)."""
        self._offers.discard((kind, name))

    def goal_started(self, op_id: OpId, handle: GoalHandle) -> None:
        """A goal of this connection is in progress and waits for its result."""
        self._goals[op_id] = handle
        self._pending_goals += 1

    def goal_finished(self, op_id: OpId, handle: GoalHandle) -> None:
        """A counted goal has its result: forget it, unless a newer goal took its id."""
        self._pending_goals -= 1
        if self._goals.get(op_id) is handle:
            del self._goals[op_id]

    def clear(self) -> None:
        """Close every subscription and forget everything (the connection closed)."""
        for subscription in self._subscriptions.values():
            subscription.close()
        self._subscriptions.clear()
        self._advertisements.clear()
        self._offers.clear()
        self._goals.clear()
