"""The connection graph for one Foxglove client, without I/O (docs/foxglove.md).

After ``subscribeConnectionGraph`` the client gets the whole graph in one
``connectionGraphUpdate`` (even an empty one), then what changed: topics and
services new or whose nodes changed (with all their nodes), and the names gone
(``removedTopics``: neither published nor subscribed any more;
``removedServices``), as the Foxglove SDK's server computes them. The ids are
node names, as foxglove_bridge sends them (``/rwt_client_3``, ``/rosapi``, a
ROS 2 node's own name through the link). What the client sees is the session's
``GraphIndex`` (the change feed, under the one visibility rule); a change marks
its name, and an update looks at the marked names only. While an update waits
unsent in the queue no other is made: the next one holds the changes since the
last sent, so a client that does not read holds one. A client that unsubscribes
and subscribes again while its last update waits gets no second whole graph
(that one, then the changes); the whole graph is made once per version of the
graph, so churning the subscription costs no walk of the graph each time.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from rwt_graph.feed import EntityKind

from .protocol import AdvertisedService, ConnectionGraphUpdate, PublishedTopic, SubscribedTopic

if TYPE_CHECKING:
    from rwt_graph.feed import GraphChange
    from rwt_protocol.runtime.outbox import OutFrame

    from .graphindex import GraphIndex
    from .output import SessionOutput

__all__ = ["ConnectionGraph", "GraphView"]

Nodes = dict[str, frozenset[str]]  # name -> node names


@dataclass(frozen=True, slots=True)
class GraphView:
    """Who publishes, subscribes to and provides what: name -> node names."""

    published: Nodes = field(default_factory=dict)
    subscribed: Nodes = field(default_factory=dict)
    services: Nodes = field(default_factory=dict)


def view_of(
    index: GraphIndex, topics: set[str] | None = None, services: set[str] | None = None
) -> GraphView:
    """The graph as the client sees it: every name, or only ``topics`` and ``services``."""
    if topics is None:
        topics = set(index.names(EntityKind.PUBLISHER)) | set(index.names(EntityKind.SUBSCRIPTION))
    if services is None:
        services = set(index.names(EntityKind.SERVICE))
    found: tuple[Nodes, Nodes, Nodes] = ({}, {}, {})
    for name in topics:
        for nodes, kind in ((found[0], EntityKind.PUBLISHER), (found[1], EntityKind.SUBSCRIPTION)):
            held = index.nodes(kind, name)
            if held:
                nodes[name] = held
    for name in services:
        held = index.nodes(EntityKind.SERVICE, name)
        if held:
            found[2][name] = held
    return GraphView(*found)


def diff(old: GraphView, new: GraphView) -> ConnectionGraphUpdate | None:
    """What a client that saw ``old`` is told to see ``new``; None if nothing changed."""
    published = [
        PublishedTopic(name, sorted(ids))
        for name, ids in sorted(new.published.items())
        if old.published.get(name) != ids
    ]
    subscribed = [
        SubscribedTopic(name, sorted(ids))
        for name, ids in sorted(new.subscribed.items())
        if old.subscribed.get(name) != ids
    ]
    services = [
        AdvertisedService(name, sorted(ids))
        for name, ids in sorted(new.services.items())
        if old.services.get(name) != ids
    ]
    removed_topics = sorted(
        (old.published.keys() | old.subscribed.keys())
        - new.published.keys()
        - new.subscribed.keys()
    )
    removed_services = sorted(old.services.keys() - new.services.keys())
    if not (published or subscribed or services or removed_topics or removed_services):
        return None
    return ConnectionGraphUpdate(
        publishedTopics=published,
        subscribedTopics=subscribed,
        advertisedServices=services,
        removedTopics=removed_topics,
        removedServices=removed_services,
    )


_EMPTY = ConnectionGraphUpdate(
    publishedTopics=[],
    subscribedTopics=[],
    advertisedServices=[],
    removedTopics=[],
    removedServices=[],
)


class ConnectionGraph:
    """One client's subscription to the connection graph.

    Args:
        index: what the client sees of the graph (kept by the session from the feed).
        out: where updates go (``tracked``: one waits in the queue at most).
    """

    def __init__(self, index: GraphIndex, out: SessionOutput) -> None:
        self._index = index
        self._out = out
        self._following = False
        self._sent: GraphView | None = None  # what the client knows once it read every update
        self._update: OutFrame | None = None
        self._topics: set[str] = set()  # names changed since the last update
        self._services: set[str] = set()
        self._whole: tuple[int, GraphView] | None = None  # the whole graph at a version

    @property
    def subscribed(self) -> bool:
        """Whether the client follows the graph."""
        return self._following

    def touched(self, change: GraphChange) -> None:
        """A change of the graph the client sees: its name goes in the next update."""
        if self._sent is None:
            return
        if change.kind is EntityKind.SERVICE:
            self._services.add(change.name)
        elif change.kind is not EntityKind.ACTION:
            self._topics.add(change.name)

    def subscribe(self) -> None:
        """Send the whole graph now, and its changes from then on."""
        if self._following:
            self._out.error("subscribeConnectionGraph: already subscribed")
            return
        self._following = True
        if self._sent is not None and self._out.unsent(self._update):  # type: ignore[arg-type]
            return  # the last update waits: it, then the changes since, will do
        version = self._index.version
        if self._whole is None or self._whole[0] != version:
            self._whole = (version, view_of(self._index))
        view = self._whole[1]
        self._sent = view
        self._topics.clear()
        self._services.clear()
        # the whole graph, even empty: the first update is always sent, as the SDK does
        self._update = self._out.tracked(diff(GraphView(), view) or _EMPTY)

    def unsubscribe(self) -> None:
        """Stop the updates."""
        if not self._following:
            self._out.error("unsubscribeConnectionGraph: not subscribed")
            return
        self._following = False
        if self._update is None or not self._out.unsent(self._update):
            self._sent = None  # the client has it all: a new subscription starts anew
            self._topics.clear()
            self._services.clear()

    def sync(self) -> bool:
        """Send what changed since the last update, if that one left the queue.

        Returns:
            Whether an update was queued.
        """
        sent = self._sent
        if not self._following or sent is None or not (self._topics or self._services):
            return False
        if self._update is not None and self._out.unsent(self._update):
            return False
        topics, services = self._topics, self._services
        self._topics, self._services = set(), set()
        now = view_of(self._index, topics, services)
        old = GraphView(
            {name: ids for name in topics if (ids := sent.published.get(name))},
            {name: ids for name in topics if (ids := sent.subscribed.get(name))},
            {name: ids for name in services if (ids := sent.services.get(name))},
        )
        if self._whole is not None and sent is self._whole[1]:  # shared: copied once
            sent = self._sent = GraphView(
                dict(sent.published), dict(sent.subscribed), dict(sent.services)
            )
        _merge(sent.published, topics, now.published)
        _merge(sent.subscribed, topics, now.subscribed)
        _merge(sent.services, services, now.services)
        update = diff(old, now)
        if update is None:
            return False
        self._update = self._out.tracked(update)
        return True


def _merge(known: Nodes, names: set[str], now: Nodes) -> None:
    """Take the entries of ``names`` in ``known`` from ``now`` (gone where ``now`` lacks them)."""
    for name in names:
        ids = now.get(name)
        if ids is None:
            known.pop(name, None)
        else:
            known[name] = ids
