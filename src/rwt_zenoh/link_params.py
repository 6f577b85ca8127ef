"""Parameters across processes, through ROS 2's parameter services of each node.

Provider side: every node with parameters in this graph answers the six
parameter services of an rclpy node on Zenoh (``/<node>/list_parameters``,
``get_parameters``, ``set_parameters``, ``describe_parameters``,
``get_parameter_types``, ``set_parameters_atomically``: ``PARAM_SERVICES``),
from and into the graph's parameter store (``rwt_graph.parameters.services``).

Caller side: a remote node's ``list_parameters`` token makes the link keep a
copy of that node's parameters in this graph's store (``rwt_graph.parameters.replicas``,
shared with the ROS 2 link), read through the node's parameter services, which
the link mirrors into the graph, so rosapi here lists and reads them; a change
made here to a copy (rosapi ``set_param``) is sent to the node's
``set_parameters``; the copy goes with the node's token. ROS 2 parameters keep
their type; rwt's store does too.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from rwt_graph.calls import guarded
from rwt_graph.parameters.replicas import ParamReplicas
from rwt_graph.parameters.services import answer
from rwt_graph.parameters.wire import PARAM_SERVICES, from_wire, to_wire
from rwt_protocol.errors import RwtError

from .payload import decode_message, encode_message, service_hash
from .wire import SERVICES_QOS, Topic, WireError, dds_type_name

if TYPE_CHECKING:
    from collections.abc import Callable

    import zenoh
    from rwt_graph.mirror import RemoteEntity
    from rwt_graph.parameters.store import ParamValue
    from rwt_protocol.ports import ClientId

    from .link import ZenohLink

__all__ = ["ParamLink"]

logger = logging.getLogger("rwt.zenoh")

SERVICES = PARAM_SERVICES
REFRESH_SWEEPS = 5
"""Replicas are refreshed every this many sweeps (0.5 s with the default sweep)."""


class ParamLink:
    """The parameter half of a ``ZenohLink`` (see the module text)."""

    def __init__(self, link: ZenohLink) -> None:
        self.link = link
        registry = link.graph.registry
        self._types = {part: registry.service(name) for part, name in SERVICES.items()}
        self._value_type = registry.message("rcl_interfaces/msg/ParameterValue")
        self._offers: dict[str, list[Any]] = {}
        self._remote_nodes: dict[str, ClientId] = {}  # node -> its list_parameters service
        self._replicas = ParamReplicas(link.graph, link.caller, REFRESH_SWEEPS)
        self._node_of: dict[ClientId, str] = {}  # the node of each remote: no walk per token

    # ---- values ------------------------------------------------------------------

    def to_wire(self, value: ParamValue) -> dict[str, object]:
        """A parameter value as ``rcl_interfaces/msg/ParameterValue`` (internal form)."""
        return to_wire(self._value_type, value)

    @staticmethod
    def from_wire(msg: dict[str, object]) -> object:
        """The value of a ``ParameterValue``; None when NOT_SET.

        Raises:
            ParameterError: an unknown type code.
        """
        return from_wire(msg)

    # ---- provider side --------------------------------------------------------------

    def sweep(self) -> None:
        """Offer each local node's parameter services; refresh the replicas now and then."""
        link = self.link
        local = {node for node in link.graph.params.nodes() if node not in self._remote_nodes}
        for node in list(self._offers):
            if node not in local:
                for handle in self._offers.pop(node):
                    guarded("undeclaring a parameter service", handle.undeclare)
        for node in local - self._offers.keys():
            try:
                self._offer(node)
            except (RwtError, WireError) as exc:
                logger.debug("zenoh link: parameters of %s are not shared: %s", node, exc)
        self._replicas.sweep(set(self._remote_nodes))

    def _offer(self, node: str) -> None:
        link = self.link
        handles: list[Any] = []
        for part, srvtype in self._types.items():
            hash_text = service_hash(link.graph.registry, srvtype)
            topic = Topic(f"{node}/{part}", dds_type_name(srvtype.name), hash_text, SERVICES_QOS)
            handles += link.declare_service(node, topic, self._on_query_thread(node, part))
        self._offers[node] = handles

    def _on_query_thread(self, node: str, part: str) -> Callable[[zenoh.Query], None]:
        def on_query(query: zenoh.Query) -> None:  # a Zenoh thread
            self.link.soon(self._answer, node, part, query)

        return on_query

    def _answer(self, node: str, part: str, query: zenoh.Query) -> None:
        registry = self.link.graph.registry
        srvtype = self._types[part]
        try:
            payload = query.payload
            request = decode_message(
                registry, srvtype.request, b"" if payload is None else payload.to_bytes()
            )
            response = answer(self.link.graph, node, part, request)
            self.link.reply(query, encode_message(registry, srvtype.response, response))
        except (RwtError, WireError) as exc:
            query.reply_err(f"{node}/{part} failed: {exc}")
        finally:
            query.drop()  # type: ignore[no-untyped-call]

    # ---- caller side --------------------------------------------------------------

    def mirror(self, client: ClientId, entity: RemoteEntity) -> None:
        """Keep a copy of the node's parameters if ``entity`` is its ``list_parameters``."""
        suffix = "/list_parameters"
        if not entity.name.endswith(suffix) or entity.type_name != SERVICES["list_parameters"]:
            return
        node = entity.name[: -len(suffix)]
        if node in self._offers or node in self._remote_nodes:
            return  # this process's own node, or already held
        self._remote_nodes[node] = client
        self._node_of[client] = node

    def unmirror(self, client: ClientId) -> None:
        """Drop the copy of ``client``'s node (its token went)."""
        node = self._node_of.pop(client, None)
        if node is not None and self._remote_nodes.get(node) == client:
            del self._remote_nodes[node]
            self._replicas.sweep(set(self._remote_nodes))

    def close(self) -> None:
        """Withdraw the services and forget the replicas."""
        for handles in self._offers.values():
            for handle in handles:
                guarded("undeclaring a parameter service", handle.undeclare)
        self._offers.clear()
        self._replicas.close()
        self._remote_nodes.clear()
        self._node_of.clear()
