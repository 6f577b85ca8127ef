"""Copies of other nodes' parameters in this graph's store, through their parameter services.

A link that mirrors another middleware's services into the graph (the ROS 2
link) gets a node's ``<node>/list_parameters``, ``get_parameters`` and
``set_parameters`` as graph services; ``ParamReplicas`` calls them through the
graph, like any caller, so rosapi's ``get_param_names``, ``get_param`` and
``set_param`` reach that node: its parameters are refreshed every
``refresh_sweeps`` sweeps into the store, a change made here to a replica
(rosapi ``set_param``) is sent to the node's ``set_parameters``, and the copy
goes with the node. The copies are the node's (``Parameters.own``): rosapi's
``set_param`` on one asks the node's ``set_parameters`` and answers what the node
answered (a refusal with the node's reason), and the store takes the node's value.

A node may list more than the store lets it hold (its share,
``params.NODE_SHARE``): the copy then holds the first names of its listing that
fit, and the rest is left out without being tried again each refresh. Names
past the room left are not even fetched while there is no room; a value the
store refused (past the node's share of bytes, a name it cannot hold) is tried
again only after a back-off of 1 refresh, doubling to ``MAX_RETRY_REFRESHES``.
A copy that becomes partial is logged once (``event=param_copy_partial``, at
most once per episode of the node: ``ratelog.EpisodeLog``), not per refresh.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING

from rwt_protocol.errors import RwtError

from ..async_calls import call_service
from ..calls import guarded
from ..ratelog import EpisodeLog
from .store import ParameterError, ParameterStoreFullError, as_held
from .wire import from_wire, to_wire

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId

    from ..graph import Graph
    from .store import Parameters, ParamValue

__all__ = ["MAX_RETRY_REFRESHES", "NODE_SET_TIMEOUT_S", "REFRESH_SWEEPS", "ParamReplicas"]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a node decides what it lists, and how often

REFRESH_SWEEPS = 5
"""Replicas are refreshed every this many sweeps of the link."""

MAX_RETRY_REFRESHES = 32
"""Refreshes a refused value waits at most before it is tried again (the back-off's cap)."""

NODE_SET_TIMEOUT_S = 5.0
"""Seconds rosapi's ``set_param`` waits for a node's ``set_parameters`` answer."""


@dataclass
class _Copy:
    """What the store holds of one node, and what it left out."""

    held: set[str] = field(default_factory=set)
    refused: set[str] = field(default_factory=set)  # values refused: not fetched until retry
    retry_in: int = 0  # refreshes until ``refused`` is tried again
    backoff: int = 1  # the wait after the next refusal, refreshes
    partial: bool = False  # the last copy left names out (logged when it became so)


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
        self._copies: dict[str, _Copy] = {}  # node -> what the store holds of it
        self._applying = False
        self._ticks = 0
        self._stop: Callable[[], None] | None = graph.params.watch(self._changed)

    @property
    def nodes(self) -> frozenset[str]:
        """The nodes whose parameters are copies here."""
        return frozenset(self._copies)

    def sweep(self, nodes: set[str], *, tick: bool = True) -> None:
        """Hold copies of exactly ``nodes``' parameters; refresh them now and then.

        ``tick``: this sweep counts toward ``refresh_sweeps`` (a link's periodic
        sweep does; one a graph change asked for in between does not).
        """
        for node in list(self._copies):
            if node not in nodes:
                self._forget(node)
        self._ticks += tick
        for node in nodes:
            if node not in self._copies:
                self._copies[node] = _Copy()
                self.graph.params.own(node, partial(self._set_on_node, node))
                self._refresh(node)
            elif self._ticks % self.refresh_sweeps == 0:
                self._refresh(node)

    def _call(
        self, node: str, part: str, args: dict[str, object], then: Callable[..., None]
    ) -> None:
        def reply(ok: bool, values: object) -> None:
            if ok and node in self._copies and isinstance(values, dict):
                guarded(f"{node}/{part} reply", partial(then, values))

        try:
            self.graph.port.call_service(self.caller, f"{node}/{part}", args, reply)
        except RwtError as exc:  # its services are not (yet) in the graph
            logger.debug("parameters of %s: %s", node, exc)

    def _forget(self, node: str) -> None:
        self.graph.params.own(node, None)
        self._apply(node, {})
        del self._copies[node]

    async def _set_on_node(self, node: str, param: str, value: ParamValue) -> tuple[bool, str]:
        """Set ``param`` on ``node`` itself; ``(successful, reason)`` as the node answered.

        A value the node accepted is held at once, so that whoever asked reads it
        back right after the answer (rosapi's ``get_param``, a Foxglove client's
        ``setParameters`` answer); the refresh this starts then takes the node's
        own values, whatever the answer (``NodeSetter``). A list of octets for a
        byte array the copy holds goes as that byte array (``store.as_held``).
        """
        value = as_held(self.graph.params.get(f"{node}:{param}", None), value)
        wire = to_wire(self._value_type, value)
        request = {"parameters": [{"name": param, "value": wire}]}
        try:
            response = await call_service(
                self.graph, f"{node}/set_parameters", request, timeout_s=NODE_SET_TIMEOUT_S
            )
        except RwtError as exc:
            return False, f"node {node} did not set {param}: {exc.message}"
        finally:
            if node in self._copies:
                self._refresh(node)
        results = response.get("results")
        result = results[0] if isinstance(results, list) and results else None
        if not isinstance(result, dict):
            return False, f"node {node} answered no result for {param}"
        successful = result.get("successful") is True
        if successful:
            self._hold(node, param, value)
        return successful, str(result.get("reason", ""))

    def _hold(self, node: str, param: str, value: ParamValue) -> None:
        """Make the copy of ``node`` hold ``value`` for ``param`` (no echo to the node)."""
        copy = self._copies.get(node)
        if copy is None:  # the node went meanwhile
            return
        self._applying = True
        try:
            _put(self.graph.params, f"{node}:{param}", value)
            copy.held.add(param)
        except ParameterError:  # no room: the refresh decides, as for any value
            pass
        finally:
            self._applying = False

    def _refresh(self, node: str) -> None:
        def listed(values: dict[str, object]) -> None:
            result = values.get("result")
            names = result.get("names", []) if isinstance(result, dict) else []
            listing = list(dict.fromkeys(n for n in names if isinstance(n, str)))
            wanted = self._wanted(node, listing)
            left_out = len(listing) - len(wanted)
            self._call(node, "get_parameters", {"names": wanted}, partial(got, wanted, left_out))

        def got(names: list[str], left_out: int, values: dict[str, object]) -> None:
            items = values.get("values")
            found = {
                name: from_wire(item)
                for name, item in zip(names, items if isinstance(items, list) else [], strict=False)
                if isinstance(item, dict)
            }
            self._apply(node, {k: v for k, v in found.items() if v is not None}, left_out)

        self._call(node, "list_parameters", {"prefixes": [], "depth": 0}, listed)

    def _wanted(self, node: str, listing: list[str]) -> list[str]:
        """The names of ``listing`` (``node``'s, in its order) worth fetching now.

        Those held, and as many others as the node has room for (counting the room
        held names gone from the listing free), but none refused until its retry.
        """
        copy = self._copies[node]
        names = set(listing)
        copy.refused &= names  # a name gone and back is new
        if copy.refused:
            copy.retry_in -= 1
            if copy.retry_in <= 0:
                copy.refused.clear()
        try:
            room = self.graph.params.room(node) + len(copy.held - names)
        except ParameterError:  # a node name the store cannot hold: nothing fits
            room = 0
        wanted: list[str] = []
        for name in listing:
            if name in copy.held:
                wanted.append(name)
            elif room > 0 and name not in copy.refused:
                wanted.append(name)
                room -= 1
        return wanted

    def _apply(self, node: str, values: dict[str, object], left_out: int = 0) -> None:
        """Make the store's copy of ``node`` hold exactly ``values`` (no echo to the node).

        ``left_out``: names of the node's listing not fetched (no room for them).
        """
        params = self.graph.params
        copy = self._copies.get(node)
        held = set() if copy is None else copy.held
        refused: dict[str, str] = {}  # name -> why
        self._applying = True
        try:
            for name in held - values.keys():
                guarded(f"forgetting {node}:{name}", partial(params.delete, f"{node}:{name}"))
            for name, value in values.items():
                try:
                    _put(params, f"{node}:{name}", value)
                except ParameterError as exc:
                    refused[name] = str(exc)
        finally:
            self._applying = False
        if copy is not None:  # a held name refused a new value keeps its old one
            copy.held = {name for name in values if name not in refused or name in held}
            self._left_out(node, copy, refused, left_out)

    def _left_out(self, node: str, copy: _Copy, refused: dict[str, str], left_out: int) -> None:
        """Remember what the store refused of ``node``; log a copy that became partial."""
        if refused:
            copy.refused |= refused.keys()
            copy.retry_in = copy.backoff
            copy.backoff = min(2 * copy.backoff, MAX_RETRY_REFRESHES)
        elif not copy.refused:
            copy.backoff = 1
        missing = left_out + len(refused)
        was, copy.partial = copy.partial, missing > 0
        if not missing or was:
            return
        try:
            reason = next(iter(refused.values()), None) or self.graph.params.room_problem(node)
        except ParameterError as exc:
            reason = str(exc)
        _episodes.log(
            logging.WARNING,
            f"param_copy_partial {node}",
            "event=param_copy_partial node=%s held=%d left_out=%d reason=%r",
            node,
            len(copy.held),
            missing,
            reason,
        )

    def _changed(self, name: str, value: ParamValue | None) -> None:
        """A change in the store: one made here to a copy goes to its node."""
        if self._applying:
            return
        node, _, param = name.partition(":")
        copy = self._copies.get(node)
        if copy is None:
            return
        if value is None:  # the store holds it, or not: the copy's to forget
            copy.held.discard(param)
        else:
            copy.held.add(param)
        # the store holds only values ROS 2 parameters can (``params.ros2_value``)
        wire = self._value_type.default() if value is None else to_wire(self._value_type, value)
        request: dict[str, object] = {"parameters": [{"name": param, "value": wire}]}
        self._call(node, "set_parameters", request, lambda _: self._refresh(node))

    def close(self) -> None:
        """Stop watching and drop every copy."""
        if self._stop is not None:
            self._stop()
            self._stop = None
        for node in list(self._copies):
            self._forget(node)


def _put(params: Parameters, name: str, value: object) -> None:
    """Make parameter ``name`` hold ``value``, replacing it whole if it keeps another type.

    Raises:
        ParameterStoreFullError: no room for it (the store's or the node's share).
        ParameterError: a name or value the store cannot hold, or a read-only one.
    """
    if params.get(name, None) == value:
        return
    try:
        params.set(name, value)
    except ParameterStoreFullError:
        raise
    except ParameterError:  # declared here with another type: the node's copy wins
        if not params.has(name):
            raise
        params.set_all([(name, None), (name, value)])
