"""The mirror of a link: the other middleware's entities as participants of the graph.

Both links (``rwt_zenoh``, ``rwt_ros2``) describe what the other side has as
``RemoteEntity`` values, each under a participant id of the link's prefix, and
hand them to one ``Mirror``, which follows the remote-entity rules of
``rwt_graph.link`` (its module text, "Remote entities" and "Cleanup"):

- a node is bound (``Nodes.bind``); a publisher or subscription is mirrored by
  ``mirror_endpoint`` (a publisher latched when it is transient local);
- a service or action is advertised with the provider the link makes for it
  (``RemoteSide``), unless one already answers under that name (a local one,
  or another remote one): then it waits, and is tried again each ``retry``,
  so it takes over once the other provider goes (the provider-exists rule);
- an entity under a private name is ignored; one the graph refuses (an unknown
  type, another type on its topic, a reserved topic, a check of the link's)
  is skipped with one log line per episode, and not tried again while it lives;
- an entity that goes, or every entity when the link stops, is released
  (``GraphCore.release``: its services fail their callers, D15; its latched
  message goes, D13), and the link is told (``RemoteSide.released``).

A link whose discovery reports changes (Zenoh's liveliness tokens) calls ``add``
and ``remove``; one that reads the whole graph each sweep (rclpy) calls
``apply`` with the snapshot, which diffs it against what is mirrored. No network
I/O here: the link supplies discovery, transport and codecs.
"""

from __future__ import annotations

import enum
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from rwt_protocol.errors import RwtError

from .link import Kind, mirror_endpoint

if TYPE_CHECKING:
    from collections.abc import Mapping

    from rwt_protocol.ports import ActionProvider, ClientId, ServiceProvider

    from .graph import Graph
    from .link import LinkRules
    from .ratelog import EpisodeLog

__all__ = ["Mirror", "RemoteEntity", "RemoteKind", "RemoteSide"]


class RemoteKind(enum.Enum):
    """The kinds of entity of the other middleware a link mirrors."""

    NODE = "node"
    PUBLISHER = "publisher"
    SUBSCRIPTION = "subscription"
    SERVICE = "service"
    ACTION = "action"


@dataclass(frozen=True)
class RemoteEntity:
    """One entity of the other middleware, as its discovery describes it.

    Two values are equal when every field is, so a snapshot's entity that
    changed under the same participant id is released and mirrored again.

    Attributes:
        kind: what it is.
        node: its node's fully qualified name (``/ns/name``); a node's own name.
        name: its topic, service or action name; "" for a node.
        type_name: its message, service or action type (``pkg/msg/Name``); "" for a node.
        latched: a publisher's durability is transient local (D13).
        gid: a publisher's GID (16 bytes), which its samples carry; b"" if none.
        detail: the link's own description (hashable), for its checks and
            providers: rmw_zenoh's topic of the token, rclpy's endpoint.
    """

    kind: RemoteKind
    node: str
    name: str = ""
    type_name: str = ""
    latched: bool = False
    gid: bytes = b""
    detail: object = None


class RemoteSide(Protocol):
    """What a link supplies its mirror: checks, and providers that call across."""

    def check_endpoint(self, entity: RemoteEntity) -> None:
        """Refuse a publisher or subscription the graph must not take.

        Raises:
            RwtError: it is refused; the text is logged as the skip's reason.
        """
        ...

    def service_provider(self, client: ClientId, entity: RemoteEntity) -> ServiceProvider:
        """The graph's provider of a remote service, calling it across the link.

        Raises:
            RwtError: the service type is unknown here.
        """
        ...

    def action_provider(self, client: ClientId, entity: RemoteEntity) -> ActionProvider:
        """The graph's provider of a remote action, sending its goals across the link.

        Raises:
            RwtError: the action type is unknown here.
        """
        ...

    def released(self, client: ClientId, entity: RemoteEntity, provider: object) -> None:
        """``entity`` went (or the link stops): drop what the link holds for it.

        ``provider`` is the one ``service_provider`` or ``action_provider``
        made for it, else None; the graph has released ``client`` already.
        """
        ...


@dataclass(eq=False)
class _Mirrored:
    """A remote entity in the table and what stands for it in the graph."""

    entity: RemoteEntity
    provider: object = None
    mirrored: bool = False
    refused: bool = False  # private, or refused by the graph: not tried again


class Mirror:
    """Mirrors remote entities into a graph and releases them (see the module text).

    Args:
        graph: the linked graph (touched on the event loop only).
        rules: the link's rules (its private names).
        side: the link's checks and providers.
        log: the link's log of what peers cause (one line per episode).
        event: the prefix of the skip lines' event (``zenoh`` -> ``event=zenoh_skip``).
        episode_per_entity: one episode per refused entity rather than per kind:
            for a ROS 2 graph, whose nodes are the robot's own; a Zenoh peer's
            tokens could invent names without end, so there it is per kind
            (docs/limits.md, "Logs a peer can trigger").
    """

    def __init__(
        self,
        graph: Graph,
        rules: LinkRules,
        side: RemoteSide,
        log: EpisodeLog,
        *,
        event: str,
        episode_per_entity: bool = False,
    ) -> None:
        self.graph = graph
        self.rules = rules
        self.side = side
        self.log = log
        self.event = event
        self.episode_per_entity = episode_per_entity
        self._table: dict[ClientId, _Mirrored] = {}
        # services and actions another provider shadows, tried again each ``retry``
        # (a set, not a walk over every remote entity per sweep)
        self._waiting: set[ClientId] = set()
        self._by_gid: dict[bytes, ClientId] = {}

    def __len__(self) -> int:
        return len(self._table)

    def __contains__(self, client: object) -> bool:
        return client in self._table

    def entity(self, client: ClientId) -> RemoteEntity | None:
        """The entity ``client`` stands for, mirrored or not; None if unknown."""
        held = self._table.get(client)
        return None if held is None else held.entity

    def mirrored(self, client: ClientId) -> bool:
        """Whether ``client`` is a participant of the graph now."""
        held = self._table.get(client)
        return held is not None and held.mirrored

    def publisher_of(self, gid: bytes) -> ClientId | None:
        """The participant of the mirrored publisher with ``gid``, else None (``Relays``)."""
        return self._by_gid.get(gid)

    # ---- changes ------------------------------------------------------------------

    def apply(self, snapshot: Mapping[ClientId, RemoteEntity]) -> None:
        """Bring the mirror in line with ``snapshot``, what the other side has now.

        An entity gone or changed is released; a new one is mirrored; the
        waiting ones are tried again.
        """
        for client, held in list(self._table.items()):
            if snapshot.get(client) != held.entity:
                self.remove(client)
        for client, entity in snapshot.items():
            if client not in self._table:
                self.add(client, entity)
        self.retry()

    def add(self, client: ClientId, entity: RemoteEntity) -> None:
        """Mirror ``entity`` as ``client`` (once it fits); nothing if ``client`` is known."""
        if client in self._table:
            return
        held = self._table[client] = _Mirrored(entity)
        if entity.kind is not RemoteKind.NODE and self.rules.is_private(entity.name):
            held.refused = True
            return
        self._mirror(client, held)

    def remove(self, client: ClientId) -> None:
        """Release ``client``'s entity (it went); nothing if ``client`` is unknown."""
        held = self._table.pop(client, None)
        if held is None:
            return
        self._waiting.discard(client)
        if held.entity.gid and self._by_gid.get(held.entity.gid) == client:
            del self._by_gid[held.entity.gid]
        if held.mirrored:
            self.graph.port.release(client)  # its services fail their callers (D15)
        self.side.released(client, held.entity, held.provider)

    def retry(self) -> None:
        """Try the waiting services and actions again (the provider shadowing one may be gone)."""
        for client in list(self._waiting):
            held = self._table.get(client)
            if held is None:
                self._waiting.discard(client)
            else:
                self._mirror(client, held)

    def close(self) -> None:
        """Release every entity (the link stops)."""
        for client in list(self._table):
            self.remove(client)

    def skip(self, kind: RemoteKind, name: str, reason: str, *, client: ClientId = "") -> None:
        """Log an entity the graph does not take, once per episode (see ``episode_per_entity``).

        A warning: what the other side carries there is lost to the graph (a type
        clash on a topic among them, docs/ros2.md).
        """
        key = f"{self.event}_skip:{client if self.episode_per_entity else kind.name}"
        self.log.log(
            logging.WARNING,
            key,
            "event=%s_skip kind=%s name=%s reason=%r",
            self.event,
            kind.value,
            name,
            reason,
        )

    # ---- mirroring ----------------------------------------------------------------

    def _mirror(self, client: ClientId, held: _Mirrored) -> None:
        entity, graph = held.entity, self.graph
        try:
            if entity.kind is RemoteKind.NODE:
                graph.nodes.bind(client, entity.node)
            elif entity.kind is RemoteKind.SERVICE:
                if self._shadowed(client, entity.name in graph.services.entries):
                    return
                held.provider = service = self.side.service_provider(client, entity)
                graph.nodes.bind(client, entity.node)
                graph.port.advertise_service(client, entity.name, entity.type_name, service)
            elif entity.kind is RemoteKind.ACTION:
                if self._shadowed(client, entity.name in graph.actions.entries):
                    return
                held.provider = action = self.side.action_provider(client, entity)
                graph.nodes.bind(client, entity.node)
                graph.port.advertise_action(
                    client, entity.name, entity.type_name, action, status=False
                )
            else:
                self.side.check_endpoint(entity)
                publisher = entity.kind is RemoteKind.PUBLISHER
                mirror_endpoint(
                    graph,
                    client,
                    entity.node,
                    Kind.PUBLISHER if publisher else Kind.SUBSCRIPTION,
                    entity.name,
                    entity.type_name,
                    latched=publisher and entity.latched,
                )
        except RwtError as exc:
            graph.nodes.forget(client)
            held.refused = True
            self._waiting.discard(client)
            self.skip(entity.kind, entity.name or entity.node, str(exc), client=client)
            return
        held.mirrored = True
        if entity.gid and entity.kind is RemoteKind.PUBLISHER:
            self._by_gid[entity.gid] = client

    def _shadowed(self, client: ClientId, shadowed: bool) -> bool:
        """Note whether another provider answers ``client``'s name (it waits meanwhile)."""
        if shadowed:
            self._waiting.add(client)
        else:
            self._waiting.discard(client)
        return shadowed
