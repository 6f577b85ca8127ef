"""The graph's change feed: every entity a participant gains or loses, announced once.

An entity is one participant's publisher or subscription of a topic, or the
service or action it provides: what rosapi lists, what a Foxglove client sees as
channels, services and its connection graph, and what a link shares outward.
Rather than rescanning the graph for them, a consumer takes the current ones
once (``ChangeFeed.snapshot``) and hears every later change (``listen``):

- a publisher added (``advertise``; a first ``publish`` without one, REF §2.3;
  ``publish_serialized`` likewise) or removed (``unadvertise``, ``release``);
- a subscription added (``subscribe``) or removed (``unsubscribe``, ``release``);
- a service or action advertised or withdrawn (its provider unadvertised it or
  left); a newer advertiser replacing one (D15) is the old owner's removal, then
  the new one's addition, each with its own version;
- the entities a link mirrors in, which take the same graph calls.

Each change carries the feed's version after it (1, 2, 3...), so a consumer
knows where it is. A topic retyped (gone, then made again with another type)
is its old entities' removals, then the new ones' additions. A publisher that
starts to latch (advertised again with ``latch``) is removed and added again
with ``latched`` true. ``node`` is the participant's node (``Nodes``) at the
time; when a participant's node changes while it holds entities (``Nodes.bind``
or ``attach`` naming it anew, ``forget``), each of its entities is announced
again: removed with the old node, added with the new one.

Announcements are synchronous: a listener hears a change once the graph's state
has it, so a listener that reads the graph sees it (or a newer state). A change
made while listeners are being told (a listener, or code it calls, changes the
graph) waits and is announced once the current one has reached every listener,
so every listener hears every change once, in version order. A listener should
still not change the graph: its change is not seen by the listeners before it.
A listener that raises is logged once per episode (``EpisodeLog``), and the
others hear the change all the same. Announcing costs one call per listener per
change; a published message costs the feed nothing.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from enum import StrEnum
from typing import TYPE_CHECKING

from .nodes import Role
from .ratelog import EpisodeLog

if TYPE_CHECKING:
    from rwt_protocol.ports import ClientId

__all__ = ["ChangeFeed", "EntityKey", "EntityKind", "FeedListener", "GraphChange"]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a listener failing on every change logs once per episode


class EntityKind(StrEnum):
    """The kinds of entity a participant holds in the graph."""

    PUBLISHER = "publisher"
    SUBSCRIPTION = "subscription"
    SERVICE = "service"
    ACTION = "action"


@dataclass(frozen=True, slots=True)
class GraphChange:
    """One entity gained or lost by one participant.

    Attributes:
        version: the feed's version after this change (1, 2, 3...).
        kind: what the entity is.
        name: the resolved topic, service or action name (``/chatter``).
        client: the participant (a connection's client id, a link's, an in-process one).
        type_name: the canonical type (``std_msgs/msg/String``, ``std_srvs/srv/SetBool``).
        added: True for an entity gained, False for one lost.
        latched: a latched publisher (transient local, D13).
        node: the node of ``client`` at the time (``Nodes.node_of``), None if it has none.
        role: what ``client`` is at the time (``Nodes.role_of``): the robot, a
            connection, or rwt's own plumbing.
    """

    version: int
    kind: EntityKind
    name: str
    client: ClientId
    type_name: str
    added: bool
    latched: bool = False
    node: str | None = None
    role: Role = Role.ROBOT

    @property
    def key(self) -> EntityKey:
        """What names the entity: ``(kind, name, client)``."""
        return (self.kind, self.name, self.client)


EntityKey = tuple[EntityKind, str, "ClientId"]
"""One entity: its kind, its resolved name and its participant."""

FeedListener = Callable[[GraphChange], None]
"""Hears each change once, in version order (see the module text)."""


class ChangeFeed:
    """The entities of one graph and the changes to them (see the module text).

    The graph (``GraphCore``) owns it and tells it each entity's state with
    ``put`` and ``drop``; the feed announces only what changed, so telling it
    twice is harmless.

    Args:
        node_of: the node of a participant now, or None (``Nodes.node_of``).
        role_of: what a participant is now (``Nodes.role_of``); the robot when None.
    """

    def __init__(
        self,
        node_of: Callable[[ClientId], str | None] | None = None,
        role_of: Callable[[ClientId], Role] | None = None,
    ) -> None:
        self._node_of = node_of or _no_node
        self._role_of = role_of or _robot
        self._version = 0
        self._current: dict[EntityKey, GraphChange] = {}  # in order of addition
        self._of_client: dict[ClientId, set[EntityKey]] = {}
        self._listeners: tuple[FeedListener, ...] = ()
        self._waiting: deque[GraphChange] | None = None  # while listeners are told

    @property
    def version(self) -> int:
        """The version of the latest change (0 before the first)."""
        return self._version

    def __len__(self) -> int:
        """The number of current entities."""
        return len(self._current)

    def listen(self, listener: FeedListener) -> Callable[[], None]:
        """Have ``listener`` hear every change from now on; returns the function that stops it.

        A listener added while a change is being announced hears the changes after
        that one; one that took a ``snapshot`` skips those whose version is at most
        the snapshot's.
        """
        self._listeners = (*self._listeners, listener)

        def stop() -> None:
            self._listeners = tuple(each for each in self._listeners if each is not listener)

        return stop

    def snapshot(self) -> tuple[int, list[GraphChange]]:
        """Every current entity (``added`` true, in order of addition) and the version they are at.

        Each entity carries the version of the change that added it. Taken with
        ``listen`` at the same time (no graph call in between), it gives a
        consumer the graph's entities as a rescan would, and every change after.
        """
        return self._version, list(self._current.values())

    def get(self, kind: EntityKind, name: str, client: ClientId) -> GraphChange | None:
        """The current entity ``(kind, name, client)`` as it was added, else None."""
        return self._current.get((kind, name, client))

    # ---- for the graph ---------------------------------------------------------------

    def put(
        self,
        kind: EntityKind,
        name: str,
        client: ClientId,
        type_name: str,
        *,
        latched: bool = False,
    ) -> None:
        """``client`` holds this entity now: announce it if it is new or changed."""
        key = (kind, name, client)
        node = self._node_of(client)
        old = self._current.get(key)
        if old is not None:
            if old.type_name == type_name and old.latched == latched and old.node == node:
                return
            self._remove(key, old)
        version, role = self._version + 1, self._role_of(client)
        change = GraphChange(version, kind, name, client, type_name, True, latched, node, role)
        self._current[key] = change
        self._of_client.setdefault(client, set()).add(key)
        self._announce(change)

    def drop(self, kind: EntityKind, name: str, client: ClientId) -> None:
        """``client`` no longer holds this entity: announce its removal if it held it."""
        key = (kind, name, client)
        old = self._current.get(key)
        if old is not None:
            self._remove(key, old)

    def renode(self, client: ClientId) -> None:
        """The node of ``client`` may have changed: announce its entities again if it did."""
        keys = self._of_client.get(client)
        if not keys:
            return
        node = self._node_of(client)
        changed = [self._current[key] for key in keys if self._current[key].node != node]
        for old in sorted(changed, key=lambda change: change.version):
            self.put(old.kind, old.name, client, old.type_name, latched=old.latched)

    def _remove(self, key: EntityKey, old: GraphChange) -> None:
        del self._current[key]
        keys = self._of_client[old.client]
        keys.discard(key)
        if not keys:
            del self._of_client[old.client]
        self._announce(replace(old, version=self._version + 1, added=False))

    def _announce(self, change: GraphChange) -> None:
        self._version = change.version
        waiting = self._waiting
        if waiting is not None:  # a listener's call changed the graph: after this change
            waiting.append(change)
            return
        waiting = self._waiting = deque((change,))
        try:
            while waiting:
                heard = waiting.popleft()
                for listener in self._listeners:
                    try:
                        listener(heard)
                    except Exception:  # a broken consumer must not hurt the graph or the others
                        _failed(listener, heard)
        finally:
            self._waiting = None


def _no_node(client: ClientId) -> str | None:
    return None


def _robot(client: ClientId) -> Role:
    return Role.ROBOT


def _failed(listener: FeedListener, change: GraphChange) -> None:
    name = getattr(listener, "__qualname__", type(listener).__qualname__)
    _episodes.log(
        logging.ERROR,
        f"feed_listener_failed {name}",
        "event=feed_listener_failed listener=%s change=%s %s of %s",
        name,
        "added" if change.added else "removed",
        change.kind.value,
        change.name,
        exc_info=True,
    )
