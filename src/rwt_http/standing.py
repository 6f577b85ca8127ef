"""The HTTP API's standing publishers: a publish's ``qos`` outlives its request (D63).

A request is a session that ends with its answer (``session``), and a topic's
offered QoS, with the messages a transient-local offer keeps, goes when its last
publisher with a ``qos`` goes (D62, D63). A client that posts a map with
``?durability=transient_local&depth=1`` means the map to stay for later
subscribers, as ``rostopic pub -l`` keeps it and as the MCP ``publish`` tool's
publisher stays for its session: so the API keeps a registration of the topic with
the publish's ``qos``, as one participant of the graph (``CLIENT_ID``), after the
request ends. It stays while the server runs, at most ``MAX_STANDING`` topics: past
that the one published on longest ago goes (its offer, and what the offer kept,
go with it unless another publisher holds them). A later publish with another
``qos`` shares the topic's offer, as any later registration does (D62).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rwt_protocol.ports import GraphPort
    from rwt_protocol.qos import QosProfile

__all__ = ["CLIENT_ID", "MAX_STANDING", "StandingOffers"]

CLIENT_ID = "http:api"
"""The graph participant that holds the API's standing registrations."""

MAX_STANDING = 256
"""Topics the API holds a standing registration of at once (docs/limits.md); the next
one lets the least recently published go."""


class StandingOffers:
    """The API's standing registrations, one per topic published with a ``qos`` (module text).

    Args:
        graph: the served graph's port.
        limit: the most topics held at once.
    """

    def __init__(self, graph: GraphPort, limit: int = MAX_STANDING) -> None:
        self._graph = graph
        self._limit = max(1, limit)
        self._held: OrderedDict[str, QosProfile] = OrderedDict()

    def __len__(self) -> int:
        return len(self._held)

    def hold(self, topic: str, type_name: str, qos: QosProfile) -> None:
        """Keep ``topic`` registered with ``qos`` past the request (the newest held last).

        Args:
            topic: the resolved topic name.
            type_name: its type, as the request's publish had it.
            qos: the publish's ``qos``.

        Raises:
            GraphError: the graph refused the registration (another type meanwhile).
        """
        if self._held.get(topic) != qos:
            self._graph.advertise(CLIENT_ID, topic, type_name, qos=qos)
            self._held[topic] = qos
        self._held.move_to_end(topic)
        while len(self._held) > self._limit:
            oldest, _ = self._held.popitem(last=False)
            self._graph.unadvertise(CLIENT_ID, oldest)

    def holds(self, topic: str) -> bool:
        """Whether ``topic`` has a standing registration."""
        return topic in self._held
