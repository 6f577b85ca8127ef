"""Each node's ROS 2 parameter services, for the graph's clients (docs/agents.md).

A ROS 2 node answers ``<node>/list_parameters``, ``get_parameters``,
``set_parameters``, ``describe_parameters``, ``get_parameter_types`` and
``set_parameters_atomically`` (``rcl_interfaces``), and tools call them rather
than rosapi (``ros2 param list``, ros-mcp's ``get_parameters``). The links offer
them to ROS 2 for every node with parameters in the store
(``parameters.services``); ``NodeParamServices`` offers the same answers to the
graph's own clients, as in-process services of each such node, made when a node
gets its first parameter and withdrawn with its last.

Each call is answered for its caller, as rosapi's are: a parameter the access
rules hide (``--params-glob``) reads as not set and cannot be set; what a client
sets is charged to it and judged by the store as rosapi's ``set_param`` is (D34).
Not offered: the nodes of connected clients (``/rwt_client_<n>``, whose
parameters go with the client), the nodes whose parameters are copies of a ROS 2
node's (``Parameters.own``: that node's services are in the graph already), and a
node whose service of that name someone else offers.
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

from ..calls import guarded, is_local
from ..nodes import CLIENT_NODE_PREFIX
from ..parameters.services import answer
from ..parameters.wire import PARAM_SERVICES

if TYPE_CHECKING:
    from rwt_protocol.ports import ClientId

    from ..graph import Graph
    from ..local import LocalService
    from ..parameters.values import ParamValue
    from .visibility import VisibilityFor

__all__ = ["NodeParamServices"]

Message = dict[str, object]


class NodeParamServices:
    """The parameter services of the store's nodes, kept in step with the store.

    Args:
        graph: the graph whose store is answered for (a ROS 2 dialect).
        visibility: the names each caller may see (access rules); None: all.
    """

    def __init__(self, graph: Graph, visibility: VisibilityFor | None) -> None:
        self._graph = graph
        self._visibility = visibility
        self._offered: dict[str, list[LocalService]] = {}  # node -> its services
        self._stop = graph.params.watch(self._changed)
        for node in sorted(graph.params.nodes()):
            self._sync(node)

    def close(self) -> None:
        """Withdraw every service and stop following the store."""
        self._stop()
        for node in list(self._offered):
            self._withdraw(node)

    def _changed(self, name: str, value: ParamValue | None) -> None:
        node, sep, _ = name.partition(":")
        if sep and (value is None or node not in self._offered):  # a set there changes nothing
            self._sync(node)

    def _wanted(self, node: str) -> bool:
        params = self._graph.params
        return (
            params.holds(node)
            and not node.startswith(CLIENT_NODE_PREFIX)
            and params.owned_by(node) is None
        )

    def _sync(self, node: str) -> None:
        """Offer ``node``'s services if it has parameters of its own, else withdraw them."""
        if not self._wanted(node):
            if node in self._offered:
                self._withdraw(node)
            return
        if node in self._offered:
            return
        services: list[LocalService] = []
        entries = self._graph.services.entries
        for part, type_name in PARAM_SERVICES.items():
            name = f"{node}/{part}"
            if name in entries:  # offered by someone else (a client, a link's mirror)
                continue
            handler = partial(self._serve, node, part)
            services.append(self._graph.create_caller_service(name, type_name, handler, node=node))
        self._offered[node] = services

    def _withdraw(self, node: str) -> None:
        for service in self._offered.pop(node, ()):
            guarded(f"withdrawing {service}", service.close)

    def _serve(self, node: str, part: str, caller: ClientId, request: Message) -> Message:
        """Answer ``<node>/<part>`` for ``caller`` (``parameters.services.answer``)."""
        visible = None
        if self._visibility is not None:
            visible = self._visibility(caller).param
        client = None if is_local(caller) else caller
        return answer(self._graph, node, part, request, client=client, visible=visible)
