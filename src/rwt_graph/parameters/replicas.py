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

A refresh fetches the values ``FETCH_SLICE`` names per ``get_parameters`` call,
one call after the other, and puts each call's values in the store as they come,
so the event loop copies at most one slice per turn, and clients are served
between slices while a node with thousands of parameters loads (docs/limits.md).
A node has one refresh at a time; one asked for meanwhile (after a ``set_param``)
follows it. A node that lists many names is refreshed less often
(``REFRESH_NAMES``): what its copy costs stays a bounded share of the loop.
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
from .values import ParameterError, ParameterStoreFullError, as_held
from .wire import from_wire, to_wire

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.ports import ClientId

    from ..graph import Graph
    from .store import Parameters
    from .values import ParamValue

__all__ = [
    "FETCH_SLICE",
    "MAX_RETRY_REFRESHES",
    "NODE_SET_TIMEOUT_S",
    "REFRESH_NAMES",
    "REFRESH_SWEEPS",
    "ParamReplicas",
]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a node decides what it lists, and how often

REFRESH_SWEEPS = 5
"""Replicas are refreshed every this many sweeps of the link."""

MAX_RETRY_REFRESHES = 32
"""Refreshes a refused value waits at most before it is tried again (the back-off's cap)."""

NODE_SET_TIMEOUT_S = 5.0
"""Seconds rosapi's ``set_param`` waits for a node's ``set_parameters`` answer."""

REFRESH_NAMES = 500
"""Names a node may list per ``refresh_sweeps``: a node listing more is refreshed less
often, every ``refresh_sweeps`` x ceil(listed / ``REFRESH_NAMES``) sweeps (20,000
names: every 40 refresh periods), so a large copy costs the event loop a bounded share."""

FETCH_SLICE = 100
"""Names one ``get_parameters`` call of a refresh asks for: the values the event loop
decodes and puts in the store in one turn (a refresh makes as many calls as it needs,
one after the other)."""


@dataclass
class _Copy:
    """What the store holds of one node, and what it left out."""

    held: set[str] = field(default_factory=set)
    refused: set[str] = field(default_factory=set)  # values refused: not fetched until retry
    retry_in: int = 0  # refreshes until ``refused`` is tried again
    backoff: int = 1  # the wait after the next refusal, refreshes
    partial: bool = False  # the last copy left names out (logged when it became so)
    refreshing: bool = False  # a refresh is under way
    listed: int = 0  # names of the node's last listing
    due: int = 0  # periodic sweeps until the next refresh
    again: bool = False  # another refresh was asked for meanwhile: it follows


@dataclass
class _Refresh:
    """One refresh of a node under way: what it fetches, and what it found so far."""

    wanted: list[str]  # the names to fetch, in the node's order
    left_out: int  # names of the listing not fetched (no room for them)
    done: int = 0  # names of ``wanted`` fetched so far
    seen: set[str] = field(default_factory=set)  # names the node gave a value
    refused: dict[str, str] = field(default_factory=dict)  # name -> why the store refused it
    calling: bool = False  # a call of ``_fetch`` is under way (an answer may come at once)
    more: bool = False  # the next slice is to be asked for by ``_fetch``'s loop


class ParamReplicas:
    """The store's copies of other nodes' parameters (see the module text).

    Args:
        graph: the graph whose store holds the copies.
        caller: the participant making the calls (the link's).
        refresh_sweeps: ``REFRESH_SWEEPS``.
        refresh_names: ``REFRESH_NAMES``.
    """

    def __init__(
        self,
        graph: Graph,
        caller: ClientId,
        refresh_sweeps: int = REFRESH_SWEEPS,
        refresh_names: int = REFRESH_NAMES,
    ) -> None:
        self.graph = graph
        self.caller = caller
        self.refresh_sweeps = refresh_sweeps
        self.refresh_names = refresh_names
        self._value_type = graph.registry.message("rcl_interfaces/msg/ParameterValue")
        self._copies: dict[str, _Copy] = {}  # node -> what the store holds of it
        self._applying = False
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
        for node in nodes:
            copy = self._copies.get(node)
            if copy is None:
                self._copies[node] = _Copy()
                self.graph.params.own(node, partial(self._set_on_node, node))
                self._refresh(node)
            elif tick:
                copy.due -= 1
                if copy.due <= 0:
                    self._refresh(node)

    def _call(
        self,
        node: str,
        part: str,
        args: dict[str, object],
        then: Callable[..., None],
        failed: Callable[[], None] | None = None,
    ) -> None:
        """Call ``node``'s ``part`` service; ``then(values)`` on an answer, else ``failed()``.

        Neither is called once the node's copy is gone.
        """
        copy = self._copies.get(node)

        def reply(ok: bool, values: object) -> None:
            if self._copies.get(node) is not copy:
                return
            handled = False

            def step() -> None:
                nonlocal handled
                then(values)
                handled = True

            if ok and isinstance(values, dict):
                guarded(f"{node}/{part} reply", step)  # a bug is logged, the copy goes on
            if not handled and failed is not None:
                failed()

        try:
            self.graph.port.call_service(self.caller, f"{node}/{part}", args, reply)
        except RwtError as exc:  # its services are not (yet) in the graph
            logger.debug("parameters of %s: %s", node, exc)
            if failed is not None:
                failed()

    def _forget(self, node: str) -> None:
        self.graph.params.own(node, None)
        self._keep(node, set())
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
                self._refresh(node, follow=True)
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

    def _refresh(self, node: str, *, follow: bool = False) -> None:
        """List ``node``'s parameters, then fetch them ``FETCH_SLICE`` at a time.

        ``follow``: while a refresh is under way, start another once it ends (a
        value was just set on the node); else none (the next sweep's will do).
        """
        copy = self._copies.get(node)
        if copy is None:
            return
        if copy.refreshing:
            copy.again = copy.again or follow
            return
        copy.refreshing = True
        periods = max(1, -(-copy.listed // self.refresh_names))  # ceil: one per REFRESH_NAMES
        copy.due = self.refresh_sweeps * periods

        def listed(values: dict[str, object]) -> None:
            result = values.get("result")
            names = result.get("names", []) if isinstance(result, dict) else []
            listing = list(dict.fromkeys(n for n in names if isinstance(n, str)))
            copy.listed = len(listing)
            wanted = self._wanted(node, listing)
            self._keep(node, set(wanted))  # gone from the node first: their room is free
            self._fetch(node, _Refresh(wanted, len(listing) - len(wanted)))

        request: dict[str, object] = {"prefixes": [], "depth": 0}
        self._call(node, "list_parameters", request, listed, partial(self._ended, node))

    def _fetch(self, node: str, refresh: _Refresh) -> None:
        """Ask for the slices of ``refresh``'s names in turn; finish it once all came.

        A slice answered at once (an in-process node) is followed by the next one
        from this loop, not from within its answer, so a long refresh nests no calls.
        """
        refresh.more = True
        while refresh.more:
            refresh.more = False
            names = refresh.wanted[refresh.done : refresh.done + FETCH_SLICE]
            if not names:
                self._finish(node, refresh)
                return
            refresh.calling = True
            request: dict[str, object] = {"names": names}
            got = partial(self._got, node, refresh, names)
            self._call(node, "get_parameters", request, got, partial(self._ended, node))
            refresh.calling = False

    def _got(
        self, node: str, refresh: _Refresh, names: list[str], values: dict[str, object]
    ) -> None:
        """One slice's values came: put them in the store, then ask for the next slice."""
        items = values.get("values")
        found: dict[str, object] = {}
        for name, item in zip(names, items if isinstance(items, list) else [], strict=False):
            try:
                value = from_wire(item) if isinstance(item, dict) else None
            except ParameterError as exc:  # a value of no ROS 2 type: refused as the store would
                refresh.refused[name] = exc.message
                continue
            if value is not None:
                found[name] = value
        refresh.seen |= found.keys()
        refresh.refused |= self._put_all(node, found)
        refresh.done += len(names)
        if refresh.calling:
            refresh.more = True  # answered at once: ``_fetch``'s loop asks for the next
        else:
            self._fetch(node, refresh)

    def _ended(self, node: str) -> None:
        """The refresh of ``node`` is over (done, or a call failed); start the one asked for."""
        copy = self._copies.get(node)
        if copy is None:
            return
        copy.refreshing = False
        if copy.again:
            copy.again = False
            self._refresh(node)

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

    def _put_all(self, node: str, values: dict[str, object]) -> dict[str, str]:
        """Make the copy of ``node`` hold ``values`` (no echo to the node); the refusals.

        Returns:
            Each name whose value the store refused, with why.
        """
        params = self.graph.params
        refused: dict[str, str] = {}  # name -> why
        self._applying = True
        try:
            for name, value in values.items():
                try:
                    _put(params, f"{node}:{name}", value)
                except ParameterError as exc:
                    refused[name] = str(exc)
        finally:
            self._applying = False
        return refused

    def _finish(self, node: str, refresh: _Refresh) -> None:
        """The last slice came: drop what the node no longer has; note what was refused."""
        copy = self._copies.get(node)
        if copy is not None:
            self._keep(node, refresh.seen)
            # a held name refused a new value keeps its old one
            copy.held |= refresh.seen - refresh.refused.keys()
            self._left_out(node, copy, refresh.refused, refresh.left_out)
        self._ended(node)

    def _keep(self, node: str, names: set[str]) -> None:
        """Delete the held parameters of ``node`` not in ``names`` (no echo to the node)."""
        copy = self._copies.get(node)
        if copy is None:
            return
        params = self.graph.params
        self._applying = True
        try:
            for name in copy.held - names:
                guarded(f"forgetting {node}:{name}", partial(params.delete, f"{node}:{name}"))
        finally:
            self._applying = False
        copy.held &= names

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
        self._call(node, "set_parameters", request, lambda _: self._refresh(node, follow=True))

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
