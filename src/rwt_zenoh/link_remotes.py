"""The Zenoh side of the link's mirror: tokens as remote entities, and their providers.

``remote_entity`` reads an rmw_zenoh liveliness token's entity as the value the
shared mirror (``rwt_graph.mirror``) takes: a ``send_goal`` service's token
stands for its action (``actions.action_of``), a transient-local publisher
latches. ``ZenohRemotes`` is the link's ``RemoteSide``: a remote service's
provider queries it (``RemoteService``), a remote action's sends its goals as
queries (``ActionLink``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt_graph.mirror import RemoteEntity, RemoteKind

from .actions import action_of
from .link_services import RemoteService
from .wire import Durability, Entity, EntityKind, Topic, ros_type_name

if TYPE_CHECKING:
    from rwt_protocol.ports import ActionProvider, ClientId

    from .link import ZenohLink
    from .link_actions import ActionLink

__all__ = ["REMOTE_KINDS", "ZenohRemotes", "full_node", "remote_entity"]

REMOTE_KINDS = {
    EntityKind.NODE: RemoteKind.NODE,
    EntityKind.PUBLISHER: RemoteKind.PUBLISHER,
    EntityKind.SUBSCRIPTION: RemoteKind.SUBSCRIPTION,
    EntityKind.SERVICE: RemoteKind.SERVICE,
}
"""The kinds of token the link mirrors (a client's token stands for nothing in the graph)."""


def full_node(entity: Entity) -> str:
    """The fully qualified name of ``entity``'s node (``/ns/name``)."""
    namespace = entity.namespace.rstrip("/")
    return f"{namespace}/{entity.node}"


def remote_entity(entity: Entity) -> RemoteEntity:
    """The remote entity a token's ``entity`` stands for (its kind in ``REMOTE_KINDS``).

    ``detail`` is the token's ``wire.Topic`` (None for a node); a publisher's
    ``gid`` is computed here, once (it hashes the whole token).

    Raises:
        WireError: the token's type is not in rmw_zenoh's form.
        KeyError: a kind not in ``REMOTE_KINDS``.
    """
    kind, node = REMOTE_KINDS[entity.kind], full_node(entity)
    topic = entity.topic
    if kind is RemoteKind.NODE or topic is None:
        return RemoteEntity(RemoteKind.NODE, node)
    type_name = ros_type_name(topic.dds_type)
    if kind is RemoteKind.SERVICE:
        found = action_of(topic.name, topic.dds_type)
        if found is not None:
            action, action_type = found
            return RemoteEntity(RemoteKind.ACTION, node, action, action_type, detail=topic)
        return RemoteEntity(kind, node, topic.name, type_name, detail=topic)
    if kind is RemoteKind.PUBLISHER:
        latched = topic.qos.durability is Durability.TRANSIENT_LOCAL
        return RemoteEntity(
            kind, node, topic.name, type_name, latched=latched, gid=entity.gid(), detail=topic
        )
    return RemoteEntity(kind, node, topic.name, type_name, detail=topic)


class ZenohRemotes:
    """The ``RemoteSide`` of the Zenoh link (see the module text).

    Args:
        link: the link the providers query through.
        actions: its action half, which mirrors remote actions.
    """

    def __init__(self, link: ZenohLink, actions: ActionLink) -> None:
        self._link = link
        self._actions = actions

    def check_endpoint(self, entity: RemoteEntity) -> None:
        """Take every endpoint: samples of another definition never match the link's keys.

        A subscriber's key carries the type hash of the graph's definition.
        """

    def service_provider(self, client: ClientId, entity: RemoteEntity) -> RemoteService:
        """The provider querying the remote service.

        Raises:
            RwtError: the service type is unknown to the registry.
        """
        topic = entity.detail
        assert isinstance(topic, Topic)
        srvtype = self._link.graph.registry.service(entity.type_name)
        return RemoteService(self._link, client, topic, srvtype)

    def action_provider(self, client: ClientId, entity: RemoteEntity) -> ActionProvider:
        """The provider sending goals to the remote action server (``ActionLink.mirror``).

        Raises:
            RwtError: the action type is unknown to the registry.
        """
        return self._actions.mirror(client, entity)

    def released(self, client: ClientId, entity: RemoteEntity, provider: object) -> None:
        """Drop the feedback subscription of a gone action server."""
        if entity.kind is RemoteKind.ACTION:
            self._actions.unmirror(client)
