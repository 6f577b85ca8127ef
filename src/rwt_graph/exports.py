"""A link's outward side: the local entities it shares, followed through the change feed.

A link shares the graph's local entities with the other middleware (the link
contract of ``rwt_graph.link``, "Local and remote"): each local publisher,
subscription, service and action whose name is not private. ``Exports`` keeps
them for one link, beside the mirror that brings the other side's in
(``rwt_graph.mirror``): it takes the graph's entities once (``ChangeFeed.snapshot``)
and then follows each change (``listen``), leaving out the link's own
participants and the private names, so no link walks the graph to find them.

What changed since the link last looked waits in one backlog, an entity at most
once with its latest state (``take``): the link applies it on its own schedule,
outside the graph's calls (declaring a token or an rclpy publisher is the
link's I/O, and a listener must not change the graph, ``rwt_graph.feed``).
``on_backlog`` tells it when the backlog stops being empty, so it can apply it
at once rather than at its next sweep. The backlog holds no more entries than
the graph has local entities, each bounded where it is made (docs/limits.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .action_status import GOAL_STATUS_ARRAY, STATUS_SUFFIX
from .calls import is_local
from .feed import EntityKind
from .parameters.wire import PARAM_SERVICES

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId

    from .feed import ChangeFeed, GraphChange
    from .link import LinkRules

__all__ = ["ExportKey", "Exports", "offered_by_links"]

ExportKey = tuple[EntityKind, "ClientId", str]
"""One local entity as a link keys its export: (kind, participant, resolved name)."""


def offered_by_links(change: GraphChange) -> bool:
    """Whether each link offers ``change``'s entity its own way, so none exports it.

    An action's ``_action/status`` publisher (``action_status``): a link that
    serves the action to its middleware publishes that status itself. A node's
    parameter service answered from the store (``parameters.offer``): each link
    offers the store's nodes' parameter services itself (docs/ros2.md).
    """
    if change.kind is EntityKind.PUBLISHER:
        return change.type_name == GOAL_STATUS_ARRAY and change.name.endswith(STATUS_SUFFIX)
    if change.kind is EntityKind.SERVICE and is_local(change.client):
        part = change.name.rpartition("/")[2]
        return PARAM_SERVICES.get(part) == change.type_name
    return False


class Exports:
    """The local entities one link shares outward (see the module text).

    Args:
        feed: the graph's change feed (``GraphCore.feed``).
        rules: the link's rules: its participant prefix and private names.
        on_backlog: called (inside the graph call that made the change) when the
            backlog was empty and no longer is; it must not change the graph,
            only arrange for ``take`` to be called soon (a loop callback).

    Attributes:
        current: every local entity to share now, by kind, then by key.
    """

    def __init__(
        self,
        feed: ChangeFeed,
        rules: LinkRules,
        *,
        on_backlog: Callable[[], None] | None = None,
    ) -> None:
        self._feed = feed
        self._rules = rules
        self.on_backlog = on_backlog
        self.current: dict[EntityKind, dict[ExportKey, GraphChange]] = {
            kind: {} for kind in EntityKind
        }
        self._backlog: dict[ExportKey, GraphChange | None] = {}
        self._since = 0  # the version of the snapshot taken
        self._stop: Callable[[], None] | None = None

    def open(self) -> None:
        """Take the graph's local entities now and follow their changes (once; the link starts)."""
        if self._stop is not None:
            return
        self._since, entities = self._feed.snapshot()
        for change in entities:
            self._note(change)
        self._stop = self._feed.listen(self._heard)

    def close(self) -> None:
        """Stop following the graph (the link stops); what is held stays readable."""
        if self._stop is not None:
            self._stop()
            self._stop = None

    @property
    def pending(self) -> bool:
        """Whether changes wait in the backlog."""
        return bool(self._backlog)

    def take(self) -> dict[ExportKey, GraphChange | None]:
        """The entities that changed since the last call, each with its state now.

        An entity's value is how it is now (its type, latching, node), or None
        when it is gone; an entity that went and came back between two calls is
        there once, with its state now. The backlog is empty afterwards.
        """
        taken, self._backlog = self._backlog, {}
        return taken

    def owners(self, kind: EntityKind) -> dict[str, GraphChange]:
        """The local entities of ``kind`` by name: for services and actions, each one's provider."""
        return {name: change for (_, _, name), change in self.current[kind].items()}

    def topics(self, kind: EntityKind) -> dict[str, tuple[str, bool]]:
        """Each topic with local entities of ``kind``: its type, and whether one of them latches."""
        found: dict[str, tuple[str, bool]] = {}
        for (_, _, name), change in self.current[kind].items():
            latched = found.get(name, (change.type_name, False))[1]
            found[name] = (change.type_name, latched or change.latched)
        return found

    def _heard(self, change: GraphChange) -> None:
        if change.version > self._since:  # not in the snapshot already
            self._note(change)

    def _note(self, change: GraphChange) -> None:
        client, name = change.client, change.name
        if self._rules.ours(client) or self._rules.is_private(name) or offered_by_links(change):
            return
        key = (change.kind, client, name)
        current = self.current[change.kind]
        if change.added:
            current[key] = change
        else:
            current.pop(key, None)
        was_empty = not self._backlog
        self._backlog[key] = current.get(key)
        if was_empty and self.on_backlog is not None:
            self.on_backlog()
