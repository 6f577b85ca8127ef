"""The client entities of this process's calls, as rmw_zenoh has one per ROS 2 client.

A ROS 2 client on rmw_zenoh is an entity of its node: a liveliness token of kind
``SC`` naming the service, its type, hash and QoS; a GID, the hash of that token;
and requests numbered from 1, each query's attachment carrying the number and the
GID (rmw_client_data.cpp). So ``ros2 service info`` counts it, and a service tells
its callers apart by GID and sequence number.

rwt calls on behalf of many participants (rosbridge clients, in-process code,
rosapi). Each caller's node gets one client entity per service it calls, declared
with its first call and withdrawn when that node leaves the graph; past
``MAX_CLIENT_ENTITIES`` at once the least recently used is withdrawn (its next
call declares it again, with a new id and GID, numbering from 1), so callers
cannot grow the tokens this process holds without bound (docs/limits.md).
"""

from __future__ import annotations

import itertools
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from rwt_graph.calls import guarded
from rwt_graph.nodes import DEFAULT_NODE

from .wire import SERVICES_QOS, EntityKind, Topic, pack_attachment

if TYPE_CHECKING:
    from collections.abc import Iterator

    from rwt_protocol.ports import ClientId

    from .link import ZenohLink

__all__ = ["LINK_NODE", "MAX_CLIENT_ENTITIES", "ClientEntities"]

LINK_NODE = "/rwt_zenoh"
"""The node of the link's own participants: relays, and calls made for no caller
of the graph (rosapi reading another process's parameters)."""

MAX_CLIENT_ENTITIES = 1024
"""Client entities (and tokens) this process declares at once, each a caller's node
and a service; past it the least recently used is withdrawn."""


@dataclass
class _Client:
    token: Any
    gid: bytes
    numbers: Iterator[int] = field(default_factory=lambda: itertools.count(1))


class ClientEntities:
    """One client entity per caller's node and service (see the module text).

    Args:
        link: the link whose session declares the tokens and whose nodes own them.
        limit: the most entities at once.
    """

    def __init__(self, link: ZenohLink, limit: int = MAX_CLIENT_ENTITIES) -> None:
        self._link = link
        self._limit = limit
        self._clients: OrderedDict[tuple[str, str], _Client] = OrderedDict()

    def attachment(self, node: str, service: str, dds_type: str, type_hash: str) -> bytes:
        """The attachment of the next request of ``node`` to ``service``: number and GID.

        Declares the client entity first, if ``node`` has none for ``service`` yet.
        ``dds_type`` and ``type_hash`` are the service's as its token names them
        (``*`` when the hash is not known here: the token carries the service's own).
        """
        key = (node, service)
        client = self._clients.get(key)
        if client is None:
            client = self._declare(node, Topic(service, dds_type, type_hash, SERVICES_QOS))
            self._clients[key] = client
            while len(self._clients) > self._limit:
                self._withdraw(next(iter(self._clients)))
        else:
            self._clients.move_to_end(key)
        return pack_attachment(next(client.numbers), time.time_ns(), client.gid)

    def _declare(self, node: str, topic: Topic) -> _Client:
        link = self._link
        entity = link.entity_of(node, EntityKind.CLIENT, topic)
        token = link.session.liveliness().declare_token(entity.token())
        return _Client(token, entity.gid())

    def caller_node(self, caller: ClientId | None) -> str:
        """The node whose client entity makes ``caller``'s calls.

        A caller's own node; in-process code that named none (``rwt.call_service``)
        calls from ``/rwt``, as Python code's handles do (``DEFAULT_NODE``); calls
        for no caller of the graph come from ``LINK_NODE``.
        """
        if caller is None:
            return LINK_NODE
        node = self._link.graph.nodes.node_of(caller)
        return DEFAULT_NODE if node is None else node

    def nodes(self) -> set[str]:
        """The nodes that own a client entity now (their node tokens must exist too)."""
        return {node for node, _ in self._clients}

    def sweep(self) -> None:
        """Withdraw the entities of nodes no longer in the graph."""
        live = self._link.graph.nodes.names() | {LINK_NODE, DEFAULT_NODE}
        for key in [k for k in self._clients if k[0] not in live]:
            self._withdraw(key)

    def _withdraw(self, key: tuple[str, str]) -> None:
        client = self._clients.pop(key)
        guarded("undeclaring a client token", client.token.undeclare)

    def close(self) -> None:
        """Withdraw every entity."""
        for key in list(self._clients):
            self._withdraw(key)
