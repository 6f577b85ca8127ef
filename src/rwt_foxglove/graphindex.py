"""The graph's entities one Foxglove client may see, kept from the change feed, without I/O.

A client's channels (topics with a publisher), services and connection graph
are what this index holds: taken once from the feed's snapshot, then kept by
each change the feed announces (``apply``), filtered by the one visibility rule
(``rwt_graph.visibility``). Nothing walks the graph again: a change costs the
index a dictionary update, and the session announces only the names a change
touched (docs/foxglove.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rwt_graph.feed import ChangeFeed, EntityKind, GraphChange
    from rwt_graph.visibility import Visibility

__all__ = ["GraphIndex"]


class GraphIndex:
    """The visible entities of one graph, by kind and name (the module's text).

    Args:
        feed: the graph's change feed; its snapshot is read here.
        visibility: what the client may see.

    Attributes:
        version: the feed's version the index is at.
    """

    def __init__(self, feed: ChangeFeed, visibility: Visibility) -> None:
        self._visibility = visibility
        self._by_name: dict[tuple[str, str], dict[str, GraphChange]] = {}
        self.version, entities = feed.snapshot()
        for change in entities:
            if visibility.sees(change):
                self._put(change)

    def apply(self, change: GraphChange) -> bool:
        """Take one change of the feed; whether it touched what the client sees."""
        if change.version <= self.version:
            return False  # in the snapshot already
        self.version = change.version
        if not self._visibility.sees(change):
            return False
        if change.added:
            self._put(change)
        else:
            key = (change.kind, change.name)
            holders = self._by_name.get(key)
            if holders is not None:
                holders.pop(change.client, None)
                if not holders:
                    del self._by_name[key]
        return True

    def _put(self, change: GraphChange) -> None:
        self._by_name.setdefault((change.kind, change.name), {})[change.client] = change

    def holders(self, kind: EntityKind, name: str) -> list[GraphChange]:
        """The entities of ``kind`` named ``name`` now, one per participant."""
        holders = self._by_name.get((kind, name))
        return [] if holders is None else list(holders.values())

    def type_of(self, kind: EntityKind, name: str) -> str | None:
        """The type of the entities of ``kind`` named ``name``, None when there is none."""
        holders = self._by_name.get((kind, name))
        return None if not holders else next(iter(holders.values())).type_name

    def names(self, kind: EntityKind) -> list[str]:
        """Every name with an entity of ``kind`` (in the order they first appeared)."""
        return [name for each, name in self._by_name if each == kind]

    def nodes(self, kind: EntityKind, name: str) -> frozenset[str]:
        """The nodes (or, without one, the participants) holding ``kind`` ``name``.

        Every holder the index keeps shows: a client connection's node
        (``/rwt_client_3``, a robot served through a rosbridge client) as any
        other; rwt's own nodes only where the visibility shows plumbing, as their
        entities are not kept otherwise (D47).
        """
        holders = self._by_name.get((kind, name))
        if not holders:
            return frozenset()
        return frozenset(change.node or change.client for change in holders.values())
