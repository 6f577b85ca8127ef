"""Copies of other nodes' parameters in this graph's store, through their parameter services.

A link that mirrors another middleware's services into the graph (the ROS 2
link) gets a node's ``<node>/list_parameters``, ``get_parameters`` and
``set_parameters`` as graph services; ``ParamReplicas`` calls them through the
graph, like any caller, so rosapi's ``get_param_names``, ``get_param`` and
``set_param`` reach that node: its parameters are refreshed every
``refresh_sweeps`` sweeps into the store, a change made here to a replica
(rosapi ``set_param``) is sent to the node's ``set_parameters``, and the copy
goes with the node.
"""

from __future__ import annotations

import logging
from functools import partial
from typing import TYPE_CHECKING

from rwt_protocol.errors import RwtError

from .calls import guarded
from .param_wire import from_wire, to_wire
from .params import ParameterError

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId

    from .graph import Graph
    from .params import Parameters, ParamValue

__all__ = ["REFRESH_SWEEPS", "ParamReplicas"]

logger = logging.getLogger("rwt.graph")

REFRESH_SWEEPS = 5
"""Replicas are refreshed every this many sweeps of the link."""


class ParamReplicas:
    """The store's copies of other nodes' parameters (see the module text).

    Args:
        graph: the graph whose store holds the copies.
        caller: the participant making the calls (the link's).
        refresh_sweeps: ``REFRESH_SWEEPS``.
    """

    def __init__(
        self, graph: Graph, caller: ClientId, refresh_sweeps: int = REFRESH_SWEEPS
    ) -> None:
        self.graph = graph
        self.caller = caller
        self.refresh_sweeps = refresh_sweeps
        self._value_type = graph.registry.message("rcl_interfaces/msg/ParameterValue")
        self._names: dict[str, set[str]] = {}  # node -> parameter names held
        self._applying = False
        self._ticks = 0
        self._stop: Callable[[], None] | None = graph.params.watch(self._changed)

    @property
    def nodes(self) -> frozenset[str]:
        """The nodes whose parameters are copies here."""
        return frozenset(self._names)

    def sweep(self, nodes: set[str]) -> None:
        """Hold copies of exactly ``nodes``' parameters; refresh them now and then."""
        for node in list(self._names):
            if node not in nodes:
                self._apply(node, {})
                del self._names[node]
        self._ticks += 1
        for node in nodes:
            if node not in self._names:
                self._names[node] = set()
                self._refresh(node)
            elif self._ticks % self.refresh_sweeps == 0:
                self._refresh(node)

    def _call(
        self, node: str, part: str, args: dict[str, object], then: Callable[..., None]
    ) -> None:
        def reply(ok: bool, values: object) -> None:
            if ok and node in self._names and isinstance(values, dict):
                guarded(f"{node}/{part} reply", partial(then, values))

        try:
            self.graph.port.call_service(self.caller, f"{node}/{part}", args, reply)
        except RwtError as exc:  # its services are not (yet) in the graph
            logger.debug("parameters of %s: %s", node, exc)

    def _refresh(self, node: str) -> None:
        def listed(values: dict[str, object]) -> None:
            result = values.get("result")
            names = list(result.get("names", [])) if isinstance(result, dict) else []
            self._call(node, "get_parameters", {"names": names}, partial(got, names))

        def got(names: list[str], values: dict[str, object]) -> None:
            items = values.get("values")
            found = {
                name: from_wire(item)
                for name, item in zip(names, items if isinstance(items, list) else [], strict=False)
                if isinstance(item, dict)
            }
            self._apply(node, {k: v for k, v in found.items() if v is not None})

        self._call(node, "list_parameters", {"prefixes": [], "depth": 0}, listed)

    def _apply(self, node: str, values: dict[str, object]) -> None:
        """Make the store's copy of ``node`` hold exactly ``values`` (no echo to the node)."""
        params = self.graph.params
        held = self._names.get(node, set())
        self._applying = True
        try:
            for name in held - values.keys():
                guarded(f"forgetting {node}:{name}", partial(params.delete, f"{node}:{name}"))
            for name, value in values.items():
                full = f"{node}:{name}"
                if params.get(full, None) != value:
                    try:
                        params.set(full, value)
                    except ParameterError:  # another type now: replace it
                        guarded(f"replacing {full}", partial(_replace, params, full, value))
            if node in self._names:
                self._names[node] = set(values)
        finally:
            self._applying = False

    def _changed(self, name: str, value: ParamValue | None) -> None:
        """A change in the store: one made here to a copy goes to its node."""
        if self._applying:
            return
        node, _, param = name.partition(":")
        if node not in self._names:
            return
        # the store holds only values ROS 2 parameters can (``params.ros2_value``)
        wire = self._value_type.default() if value is None else to_wire(self._value_type, value)
        request: dict[str, object] = {"parameters": [{"name": param, "value": wire}]}
        self._call(node, "set_parameters", request, lambda _: self._refresh(node))

    def close(self) -> None:
        """Stop watching and drop every copy."""
        if self._stop is not None:
            self._stop()
            self._stop = None
        for node in list(self._names):
            self._apply(node, {})
        self._names.clear()


def _replace(params: Parameters, name: str, value: object) -> None:
    params.delete(name)
    params.set(name, value)
