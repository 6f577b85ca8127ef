"""The graph as a protocol front end sees it: the port's calls, and what it follows beside them.

``rwt_protocol.ports.GraphPort`` holds the calls every front end makes on a
client's behalf (advertise, publish, subscribe, call, release), in the graph's
terms, and can name no graph type (layering). A front end of its own, such as
the Foxglove session (``rwt_foxglove``), needs more from the graph beside those
calls: what entities there are and how they change (the change feed, instead
of rescanning the graph), the message types, the nodes, the time a bag plays
at, the player, the spawner of async work. ``GraphFront`` is that interface;
``rwt_graph.core.GraphCore`` implements it (``Graph.port``).

Packages outside ``rwt_graph`` type against ``GraphFront`` (or ``GraphPort``),
never against ``GraphCore``: its containers (``topics``, ``services``) are the
graph's own business, and an import contract in ``pyproject.toml`` keeps them
from importing ``rwt_graph.core`` (docs/architecture.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from rwt_protocol.ports import GraphPort

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId, MessageEvent

    from .calls import Spawner
    from .clock import Clock
    from .feed import ChangeFeed
    from .playback import Playback
    from .types import TypeRegistry

__all__ = ["GraphFront", "NodeNames"]


class NodeNames(Protocol):
    """The nodes of the graph's participants, read-only (``nodes.Nodes``)."""

    def names(self) -> set[str]:
        """The nodes of every current participant."""
        ...

    def node_of(self, client: ClientId) -> str | None:
        """The node of ``client`` if it has one."""
        ...

    def clients_of(self, node: str) -> set[ClientId]:
        """The participants that belong to ``node``."""
        ...

    def host_of(self, client: ClientId) -> str | None:
        """The peer address of a connection, None for in-process participants."""
        ...


class GraphFront(GraphPort, Protocol):
    """What a protocol front end needs from the graph (see the module text)."""

    @property
    def feed(self) -> ChangeFeed:
        """Every entity a participant gains or loses (``feed.ChangeFeed``)."""
        ...

    @property
    def registry(self) -> TypeRegistry:
        """The message, service and action types (their dialect is the graph's)."""
        ...

    @property
    def nodes(self) -> NodeNames:
        """The node of each participant."""
        ...

    @property
    def clock(self) -> Clock:
        """The graph's time source now (a bag's time while one plays)."""
        ...

    @property
    def timeline(self) -> Callable[[], int | None] | None:
        """The playback's time in ns while a bag plays into the graph (or sim time), else None."""
        ...

    @property
    def playback(self) -> Playback | None:
        """The player whose clock is the ``timeline``, else None."""
        ...

    @property
    def spawner(self) -> Spawner | None:
        """Runs async jobs in the serving event loop (``calls.Spawner``); None outside a server."""
        ...

    def latched(self, topic: str) -> MessageEvent | None:
        """The latched message of ``topic`` (D13), None if it has none."""
        ...
