"""The answers of a node's ROS 2 parameter services, from the graph's parameter store.

A link offers each local node that has parameters in the store as a ROS 2 node
would: ``<node>/list_parameters``, ``<node>/get_parameters`` and
``<node>/set_parameters`` (``rcl_interfaces``). ``answer`` computes a response
from a request, both in the internal form; the link carries them (Zenoh
queries, rclpy services).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .param_wire import from_wire, to_wire
from .params import ParameterError

if TYPE_CHECKING:
    from .graph import Graph

__all__ = ["answer", "param_nodes"]


def param_nodes(graph: Graph) -> frozenset[str]:
    """The nodes that have parameters in ``graph``'s store (``/robot``)."""
    return graph.params.nodes()


def _names_of(graph: Graph, node: str) -> list[str]:
    prefix = f"{node}:"
    return [name[len(prefix) :] for name in graph.params.names() if name.startswith(prefix)]


def answer(graph: Graph, node: str, part: str, request: dict[str, object]) -> dict[str, object]:
    """The response of ``<node>/<part>`` to ``request``.

    ``part`` is ``list_parameters``, ``get_parameters`` or ``set_parameters``;
    a parameter that cannot be set gets ``successful: false`` with the reason.

    Raises:
        KeyError: another ``part``.
    """
    value_type = graph.registry.message("rcl_interfaces/msg/ParameterValue")
    params = graph.params
    if part == "list_parameters":
        return {"result": {"names": _names_of(graph, node), "prefixes": []}}
    if part == "get_parameters":
        values = []
        names = request.get("names")
        for name in names if isinstance(names, list) else []:
            value = params.get(f"{node}:{name}", None)
            values.append(value_type.default() if value is None else to_wire(value_type, value))
        return {"values": values}
    if part != "set_parameters":
        raise KeyError(part)
    results = []
    parameters = request.get("parameters")
    for parameter in parameters if isinstance(parameters, list) else []:
        assert isinstance(parameter, dict)
        name = f"{node}:{parameter['name']}"
        try:
            new = from_wire(parameter["value"])
            if new is None:
                params.delete(name)
            else:
                params.set(name, new)
            results.append({"successful": True, "reason": ""})
        except ParameterError as exc:
            results.append({"successful": False, "reason": exc.message})
    return {"results": results}
