"""The answers of a node's ROS 2 parameter services, from the graph's parameter store.

A link offers each local node that has parameters in the store as an rclpy node
would (``rclpy.parameter_service``): ``<node>/list_parameters``,
``get_parameters``, ``set_parameters``, ``describe_parameters``,
``get_parameter_types`` and ``set_parameters_atomically`` (``rcl_interfaces``).
``answer`` computes a response from a request, both in the internal form; the
link carries them (Zenoh queries, rclpy services).

The store's parameters behave as those of an rclpy node that allows undeclared
parameters: a name that is not set reads as ``NOT_SET``, and setting it creates
it with dynamic typing; parameters declared by Python code keep their type and
may be read-only (``Parameters.declare``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from .values import ParameterError, value_size
from .wire import from_wire, to_wire, type_code

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId

    from ..graph import Graph
    from .values import ParamValue

__all__ = ["MAX_ANSWER_BYTES", "MAX_REQUEST_ITEMS", "answer", "param_nodes"]

MAX_REQUEST_ITEMS = 10_000
"""Names or parameters one request may hold (the store's default ``max_params``).

A request with more is refused whole (docs/ros2.md, "Limits"): an error reply on
Zenoh, the default response for an rclpy caller; ``set_parameters_atomically``
answers ``successful: false`` with the reason."""

MAX_ANSWER_BYTES = 64 * 1024 * 1024
"""Bytes of values one ``get_parameters`` answer may hold (``value_size``).

The same large parameter named many times in one request would otherwise make
an answer of gigabytes; past this the request is refused as above."""


def param_nodes(graph: Graph) -> frozenset[str]:
    """The nodes that have parameters in ``graph``'s store (``/robot``)."""
    return graph.params.nodes()


def _names_of(graph: Graph, node: str) -> list[str]:
    return sorted(graph.params.names_of(node))


def _items(request: dict[str, object], field: str) -> list[object]:
    """The list ``field`` of ``request``, at most ``MAX_REQUEST_ITEMS`` long.

    Raises:
        ParameterError: a longer list.
    """
    items = request.get(field)
    if not isinstance(items, list):
        return []
    if len(items) > MAX_REQUEST_ITEMS:
        raise ParameterError(f"{len(items)} {field} in one request, more than {MAX_REQUEST_ITEMS}")
    return items


def answer(
    graph: Graph,
    node: str,
    part: str,
    request: dict[str, object],
    *,
    client: ClientId | None = None,
    visible: Callable[[str], bool] | None = None,
) -> dict[str, object]:
    """The response of ``<node>/<part>`` to ``request``.

    ``part`` is a key of ``wire.PARAM_SERVICES``. A parameter that cannot
    be set gets ``successful: false`` with the reason; ``set_parameters_atomically``
    sets all of its parameters or none (``Parameters.set_all``), with one result.

    Args:
        graph: whose store answers.
        node: the node (``/robot``).
        part: which service.
        request: the request in the internal form.
        client: the client that calls, charged for what it sets and judged as
            rosapi's ``set_param`` judges it (D34); None: a link, in-process code.
        visible: whether the caller may see a parameter (``/node:name``, the
            access rules); a hidden one reads as not set and cannot be set.

    Raises:
        KeyError: another ``part``.
        ParameterError: a request over ``MAX_REQUEST_ITEMS`` (except the atomic
            set, which answers it), a ``get_parameters`` answer over
            ``MAX_ANSWER_BYTES``.
    """
    asking = _Asking(graph, node, client, visible or _everything)
    if part == "set_parameters_atomically":
        return {"result": _set_atomically(asking, request)}
    return _ANSWERS[part](asking, request)


def _everything(name: str) -> bool:
    return True


@dataclass(frozen=True, slots=True)
class _Asking:
    """Who asks which node's services: the graph, the node, the client, what it sees."""

    graph: Graph
    node: str
    client: ClientId | None
    visible: Callable[[str], bool]

    def get(self, name: object) -> ParamValue | None:
        """The value of ``name`` of the node as the caller sees it; None: not set."""
        full = f"{self.node}:{name}"
        return self.graph.params.get(full, None) if self.visible(full) else None

    def settable(self, name: object) -> str:
        """``/node:name``, if the caller may see it.

        Raises:
            ParameterError: it may not.
        """
        full = f"{self.node}:{name}"
        if not self.visible(full):
            raise ParameterError(f"parameter {full} is not accessible")
        return full


def _list(asking: _Asking, request: dict[str, object]) -> dict[str, object]:
    prefixes = {prefix for prefix in _items(request, "prefixes") if isinstance(prefix, str)}
    depth = request.get("depth")
    depth = depth if isinstance(depth, int) else 0
    node, visible = asking.node, asking.visible
    names = [
        name
        for name in _names_of(asking.graph, node)
        if _listed(name, prefixes, depth) and visible(f"{node}:{name}")
    ]
    # the namespaces of the names listed, each once ("a.b" of "a.b.c"), as rclpy lists them
    spaces = dict.fromkeys(name.rpartition(".")[0] for name in names if "." in name)
    return {"result": {"names": names, "prefixes": list(spaces)}}


def _listed(name: str, prefixes: set[str], depth: int) -> bool:
    """Whether ``list_parameters`` lists ``name`` (rclpy ``Node.list_parameters``).

    No prefixes: every name with fewer than ``depth`` dots (0: every name). Else a
    name equal to a prefix, or under one (``prefix.``) with fewer than ``depth``
    dots after it (0: any). One set lookup per dot of the name, so a long list of
    prefixes costs no walk per name.
    """
    if not prefixes:
        return depth == 0 or name.count(".") < depth
    if name in prefixes:
        return True
    dot = name.find(".")
    while dot != -1:
        if name[:dot] in prefixes and (depth == 0 or name[dot + 1 :].count(".") < depth):
            return True
        dot = name.find(".", dot + 1)
    return False


def _get(asking: _Asking, request: dict[str, object]) -> dict[str, object]:
    value_type = asking.graph.registry.message("rcl_interfaces/msg/ParameterValue")
    values, size = [], 0
    for name in _items(request, "names"):
        value = asking.get(name)
        size += 0 if value is None else value_size(value)
        if size > MAX_ANSWER_BYTES:
            raise ParameterError(f"the answer would hold more than {MAX_ANSWER_BYTES} bytes")
        values.append(value_type.default() if value is None else to_wire(value_type, value))
    return {"values": values}


def _types(asking: _Asking, request: dict[str, object]) -> dict[str, object]:
    types = []
    for name in _items(request, "names"):
        value = asking.get(name)
        types.append(0 if value is None else type_code(value))  # 0: NOT_SET
    return {"types": types}


def _describe(asking: _Asking, request: dict[str, object]) -> dict[str, object]:
    graph, node = asking.graph, asking.node
    descriptor_type = graph.registry.message("rcl_interfaces/msg/ParameterDescriptor")
    descriptors = []
    for name in _items(request, "names"):
        descriptor = descriptor_type.default()
        descriptor["name"] = name  # as rclcpp: a name not set gets its name and NOT_SET
        value = asking.get(name)
        info = None if value is None else graph.params.describe(f"{node}:{name}")
        if value is not None and info is not None:
            descriptor["type"] = type_code(value)
            descriptor["read_only"] = info.read_only
            descriptor["dynamic_typing"] = info.dynamic_typing
        descriptors.append(descriptor)
    return {"descriptors": descriptors}


def _set(asking: _Asking, request: dict[str, object]) -> dict[str, object]:
    params = asking.graph.params
    results = []
    for parameter in _items(request, "parameters"):
        assert isinstance(parameter, dict)
        try:
            name = asking.settable(parameter["name"])
            new = from_wire(parameter["value"])
            if new is None:
                params.delete(name)
            else:
                params.set(name, new, client=asking.client)
            results.append({"successful": True, "reason": ""})
        except ParameterError as exc:
            results.append({"successful": False, "reason": exc.message})
    return {"results": results}


def _set_atomically(asking: _Asking, request: dict[str, object]) -> dict[str, object]:
    try:
        changes = []
        for parameter in _items(request, "parameters"):
            assert isinstance(parameter, dict)
            changes.append((asking.settable(parameter["name"]), from_wire(parameter["value"])))
        asking.graph.params.set_all(changes, client=asking.client)
    except ParameterError as exc:
        return {"successful": False, "reason": exc.message}
    return {"successful": True, "reason": ""}


_ANSWERS: dict[str, Callable[[_Asking, dict[str, object]], dict[str, object]]] = {
    "list_parameters": _list,
    "get_parameters": _get,
    "set_parameters": _set,
    "describe_parameters": _describe,
    "get_parameter_types": _types,
}
