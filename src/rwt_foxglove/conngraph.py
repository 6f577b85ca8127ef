"""The connection graph for one Foxglove client, without I/O (docs/foxglove.md).

After ``subscribeConnectionGraph`` the client gets the whole graph in one
``connectionGraphUpdate`` (even an empty one), then, at each sync, what changed: topics and
services new or whose nodes changed (with all their nodes), and the names gone
(``removedTopics``: neither published nor subscribed any more;
``removedServices``), as the Foxglove SDK's server computes them. The ids are
node names, as foxglove_bridge sends them (``/rwt_client_3``, ``/rosapi``, a
ROS 2 node's own name through the link). The access globs hide what the
client may not use. While an update waits unsent in the queue no other is
made: the next one holds the changes since the last sent, so a client that
does not read holds one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from rwt_graph.visibility import Visibility

from .protocol import AdvertisedService, ConnectionGraphUpdate, PublishedTopic, SubscribedTopic

if TYPE_CHECKING:
    from rwt_graph.port import GraphFront
    from rwt_protocol.server.access import AccessPolicy
    from rwt_protocol.server.outbox import OutFrame

    from .output import SessionOutput

__all__ = ["ConnectionGraph", "GraphView"]

Nodes = dict[str, frozenset[str]]  # name -> node names


@dataclass(frozen=True, slots=True)
class GraphView:
    """Who publishes, subscribes to and provides what: name -> node names."""

    published: Nodes = field(default_factory=dict)
    subscribed: Nodes = field(default_factory=dict)
    services: Nodes = field(default_factory=dict)


def view_of(graph: GraphFront, access: AccessPolicy) -> GraphView:
    """The graph now, as a client under ``access`` sees it. Costs one pass over the graph."""
    found: dict[str, dict[str, set[str]]] = {"publisher": {}, "subscription": {}, "service": {}}
    visible = Visibility.of(access)
    for change in graph.feed.snapshot()[1]:
        if change.kind in found and visible.sees(change):
            found[change.kind].setdefault(change.name, set()).add(change.node or change.client)
    published, subscribed, services = (
        {name: frozenset(ids) for name, ids in found[kind].items()}
        for kind in ("publisher", "subscription", "service")
    )
    return GraphView(published, subscribed, services)


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
        graph: the graph's core.
        out: where updates go (``tracked``: one waits in the queue at most).
        access: what the client may see.
    """

    def __init__(self, graph: GraphFront, out: SessionOutput, access: AccessPolicy) -> None:
        self._graph = graph
        self._out = out
        self._access = access
        self._sent: GraphView | None = None  # None: not subscribed
        self._update: OutFrame | None = None

    @property
    def subscribed(self) -> bool:
        """Whether the client follows the graph."""
        return self._sent is not None

    def subscribe(self) -> None:
        """Send the whole graph now, and its changes from then on."""
        if self._sent is not None:
            self._out.error("subscribeConnectionGraph: already subscribed")
            return
        view = view_of(self._graph, self._access)
        self._sent = view
        # the whole graph, even empty: the first update is always sent, as the SDK does
        self._update = self._out.tracked(diff(GraphView(), view) or _EMPTY)

    def unsubscribe(self) -> None:
        """Stop the updates."""
        if self._sent is None:
            self._out.error("unsubscribeConnectionGraph: not subscribed")
            return
        self._sent = None

    def sync(self) -> bool:
        """Send what changed since the last update, if that one left the queue.

        Returns:
            Whether an update was queued.
        """
        if self._sent is None or (self._update is not None and self._out.unsent(self._update)):
            return False
        view = view_of(self._graph, self._access)
        update = diff(self._sent, view)
        self._sent = view
        if update is None:
            return False
        self._update = self._out.tracked(update)
        return True
