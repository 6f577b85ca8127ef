"""Node names of the graph's participants, for rosapi (REF §7.1).

ROS lists topics, services and parameters by node. Here every participant (a
client connection, or a handle made by Python code in this process) belongs to
one node: a connection is a node of its own, ``/rwt_client_<n>``; Python code
names its node when it creates a publisher, service... (``/rwt`` by default).
Several participants may share a node name; rosapi merges what they hold.

Each participant also has a ``Role``: the server's own helpers (rosapi, the
client counts, the TF republisher) are plumbing by their node
(``SERVER_NODES``), a connection's own node marks a connection, anything else is
the robot. A Foxglove client sees only the robot by default (docs/foxglove.md).
"""

from __future__ import annotations

import itertools
import re
from enum import StrEnum
from typing import TYPE_CHECKING

from rwt_protocol.errors import GraphError
from rwt_protocol.names import resolve_name

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId

__all__ = ["CLIENT_NODE_PREFIX", "DEFAULT_NODE", "SERVER_NODES", "Nodes", "Role", "node_name"]

#: The node of Python code that does not name one.
DEFAULT_NODE = "/rwt"
#: Connections are nodes ``/rwt_client_1``, ``/rwt_client_2``... in order of arrival.
CLIENT_NODE_PREFIX = "/rwt_client_"

SERVER_NODES = frozenset({"/rosapi", "/rosbridge_websocket", "/tf2_web_republisher"})
"""The server's own nodes (rosapi's, the server's topics', the TF republisher's): their
participants are plumbing (``Role.PLUMBING``), and no client may create parameters on
them (``parameters.store``; ``rwt_graph.rosapi.ROSAPI_NODE``,
``rwt_transports.server.SERVER_NODE``, ``rwt_graph.tf.install.TF_NODE``)."""


class Role(StrEnum):
    """What a participant is to the graph's users (``Nodes.role_of``)."""

    ROBOT = "robot"
    """Python code's handles, a link's mirrored ROS or Zenoh nodes: the robot itself."""
    CONNECTION = "connection"
    """A client connection on its own node (``/rwt_client_<n>``)."""
    PLUMBING = "plumbing"
    """rwt's own helpers, on one of ``SERVER_NODES``: rosapi's services, ``/client_count``
    and ``/connected_clients``, the TF republisher's action, service and topics."""


_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def node_name(name: str) -> str:
    """Check a node name and make it absolute (``robot`` -> ``/robot``).

    Raises:
        GraphError: a part of the name is not a ROS name token
            (letters, digits, ``_``; not starting with a digit), or it is empty.
    """
    resolved = resolve_name(name)
    tokens = resolved.split("/")[1:]
    if not all(_TOKEN.match(token) for token in tokens):
        raise GraphError(f"invalid node name {name!r}")
    return resolved


class Nodes:
    """Which node each participant belongs to, and the host of each connection.

    Attributes:
        on_forget: called with ``(client, node)`` (its node, None if it had none)
            after a participant is forgotten; the parameter store releases what a
            client set (``parameters.store``).
        on_change: called with a participant whose node changed (bound anew, or
            forgotten); the graph's change feed re-announces its entities then
            (``ChangeFeed.renode``).
    """

    def __init__(self) -> None:
        self.on_forget: list[Callable[[ClientId, str | None], None]] = []
        self._names: dict[ClientId, str] = {}
        self._hosts: dict[ClientId, str] = {}
        self._connections: set[ClientId] = set()  # those ``attach`` gave a node
        self._members: dict[str, set[ClientId]] = {}  # node -> participants: no walk per query
        self._numbers = itertools.count(1)
        self.on_change: Callable[[ClientId], None] | None = None

    def attach(self, client: ClientId, *, host: str | None = None) -> str:
        """Give a connection its own node (once; later calls keep the first name).

        Args:
            client: the connection's participant id.
            host: the peer's address, reported by ROS 1 ``service_host``.

        Returns:
            The node name, ``/rwt_client_<n>``.
        """
        if host is not None:
            self._hosts[client] = host
        name = self._names.get(client)
        if name is None:
            name = f"{CLIENT_NODE_PREFIX}{next(self._numbers)}"
            self._connections.add(client)
            self.bind(client, name)
        return name

    def bind(self, client: ClientId, node: str) -> None:
        """Put an in-process participant in ``node`` (already checked by ``node_name``)."""
        was = self._leave(client)
        self._names[client] = node
        self._members.setdefault(node, set()).add(client)
        if was != node and self.on_change is not None:
            self.on_change(client)

    def forget(self, client: ClientId) -> None:
        """The participant is gone (disconnected, or its handle closed)."""
        was = self._leave(client)
        self._hosts.pop(client, None)
        self._connections.discard(client)
        if was is not None and self.on_change is not None:
            self.on_change(client)
        for hook in list(self.on_forget):
            hook(client, was)

    def _leave(self, client: ClientId) -> str | None:
        node = self._names.pop(client, None)
        if node is not None:
            members = self._members[node]
            members.discard(client)
            if not members:
                del self._members[node]
        return node

    def name_of(self, client: ClientId) -> str:
        """The node of ``client``; a participant never seen gets a client node."""
        name = self._names.get(client)
        return name if name is not None else self.attach(client)

    def node_of(self, client: ClientId) -> str | None:
        """The node of ``client`` if it has one; unlike ``name_of``, never makes one."""
        return self._names.get(client)

    def role_of(self, client: ClientId) -> Role:
        """What ``client`` is: rwt's plumbing by its node, a connection, or the robot."""
        node = self._names.get(client)
        if node in SERVER_NODES:
            return Role.PLUMBING
        return Role.CONNECTION if client in self._connections else Role.ROBOT

    def host_of(self, client: ClientId) -> str | None:
        """The peer address of a connection, None for in-process participants."""
        return self._hosts.get(client)

    def names(self) -> set[str]:
        """The nodes of every current participant."""
        return set(self._members)

    def clients_of(self, node: str) -> set[ClientId]:
        """The participants that belong to ``node``."""
        return set(self._members.get(node, ()))
