"""The ROS 2 side of the link's mirror: the graph view as remote entities, and their providers.

``entities`` turns a ``graphview.RosGraph`` into the snapshot the shared mirror
(``rwt_graph.mirror``) diffs each sweep; ``RosRemotes`` is the link's
``RemoteSide``: it refuses endpoints of another type definition (their type
hash differs) and makes the rclpy providers of ROS 2 services and actions.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt_graph.mirror import RemoteEntity, RemoteKind
from rwt_graph.types.hashes import message_type_hash
from rwt_protocol.errors import GraphError

from .actions import RosAction
from .graphview import Endpoint
from .services import RosService

if TYPE_CHECKING:
    from rwt_protocol.ports import ClientId

    from .graphview import RosGraph
    from .link import Ros2Link

__all__ = ["RosRemotes", "entities"]


def entities(view: RosGraph, prefix: str) -> dict[ClientId, RemoteEntity]:
    """What ``view`` holds, by the participant id each gets (``prefix`` starts it).

    A node is ``<prefix>node:<node>``, an endpoint ``<prefix><gid hex>``, a
    service server ``<prefix>srv:<node>:<name>``, an action server
    ``<prefix>action:<node>:<name>``: the same entity gets the same id each sweep.
    """
    found: dict[ClientId, RemoteEntity] = {}
    for node in view.nodes:
        found[f"{prefix}node:{node}"] = RemoteEntity(RemoteKind.NODE, node)
    for gid, endpoint in view.endpoints.items():
        publisher = endpoint.kind == "publisher"
        found[f"{prefix}{gid.hex()}"] = RemoteEntity(
            RemoteKind.PUBLISHER if publisher else RemoteKind.SUBSCRIPTION,
            endpoint.node,
            endpoint.topic,
            endpoint.type_name,
            latched=publisher and endpoint.qos.transient_local,
            gid=gid,
            detail=endpoint,
        )
    for (node, name), type_name in view.services.items():
        found[f"{prefix}srv:{node}:{name}"] = RemoteEntity(
            RemoteKind.SERVICE, node, name, type_name
        )
    for (node, name), type_name in view.actions.items():
        found[f"{prefix}action:{node}:{name}"] = RemoteEntity(
            RemoteKind.ACTION, node, name, type_name
        )
    return found


class RosRemotes:
    """The ``RemoteSide`` of the ROS 2 link (see the module text).

    Args:
        link: the link its providers call through.
    """

    def __init__(self, link: Ros2Link) -> None:
        self._link = link
        self._hashes: dict[str, str] = {}  # type -> the registry's RIHS01
        self._mismatched: set[bytes] = set()  # GIDs of endpoints of another definition

    def mismatched(self, gid: bytes) -> bool:
        """Whether the endpoint with ``gid`` has another type definition (its samples drop)."""
        return gid in self._mismatched

    def check_endpoint(self, entity: RemoteEntity) -> None:
        """Refuse an endpoint whose type's definition is not the graph's (another hash).

        Its bytes would decode wrongly, so its samples are dropped too.

        Raises:
            GraphError: the hashes differ; the text says how to give rwt the
                robot's definitions.
        """
        endpoint = entity.detail
        assert isinstance(endpoint, Endpoint)
        if not endpoint.type_hash:
            return  # the middleware reports none (not Iron or later)
        ours = self._hashes.get(endpoint.type_name)
        if ours is None:  # bounded: type names the registry knows
            try:
                ours = message_type_hash(self._link.graph.registry, endpoint.type_name)
            except KeyError:  # a definition the type store could not load: no hash
                ours = endpoint.type_hash
            self._hashes[endpoint.type_name] = ours
        if ours != endpoint.type_hash:
            self._mismatched.add(endpoint.gid)
            raise GraphError(
                f"{endpoint.topic}: {endpoint.node}'s {endpoint.type_name} is "
                f"{endpoint.type_hash}, rwt's definition {ours}: give rwt the robot's "
                "definitions (--interfaces, or source the robot's install)"
            )

    def service_provider(self, client: ClientId, entity: RemoteEntity) -> RosService:
        """An rclpy client of the ROS 2 service, made at its first call (``RosService``).

        Raises:
            RwtError: the service type is unknown to the registry.
        """
        srvtype = self._link.graph.registry.service(entity.type_name)
        return RosService(self._link, client, entity.name, srvtype)

    def action_provider(self, client: ClientId, entity: RemoteEntity) -> RosAction:
        """An rclpy action client of the ROS 2 action (``RosAction``).

        Raises:
            RwtError: the action type is unknown to the registry.
        """
        actiontype = self._link.graph.registry.action(entity.type_name)
        return RosAction(self._link, client, entity.name, actiontype)

    def released(self, client: ClientId, entity: RemoteEntity, provider: object) -> None:
        """Forget a gone endpoint's mismatch; destroy a gone server's rclpy client."""
        if entity.gid:
            self._mismatched.discard(entity.gid)
        if isinstance(provider, RosService | RosAction):
            provider.close()
