"""The graph's parameters for one Foxglove client, without I/O (docs/foxglove.md).

Names are foxglove_bridge's: ROS 2 ``<node>.<param>`` (``/robot.max_speed``,
the store's ``/robot:max_speed``; a node name holds no ``.``, so the first one
splits), ROS 1 the global name (``/robot/max_speed``). Values are JSON; a float
goes out with ``type: float64`` (``float64_array`` for a list of them), since
JSON writes ``1.0`` as ``1``, and comes in as a float when the client says so.
A byte array goes both ways as foxglove_bridge sends it: ``type: byte_array``
and its bytes in base64 (standard alphabet, padded).

``getParameters`` answers ``parameterValues`` with its ``id`` (none named: every
parameter the client may see); ``setParameters`` sets each parameter (no value
deletes it) and, with an ``id``, answers the values they have then. A refused
change is an error ``status`` naming it; the others are made. Parameters of a
node that owns its own (a ROS 2 node copied by the link) are set by that node,
and the answer waits for it. ``subscribeParameterUpdates`` pushes every change
made from any side (rosapi's ``set_param``, another client, the link) as
``parameterValues`` without ``id``; a deletion is the name without a value.
Changes that come while an earlier push waits in the queue are merged into the
next one (the newest value of each), so a client that does not read holds one.
"""

from __future__ import annotations

import base64
import binascii
import math
from typing import TYPE_CHECKING, Final

from rwt_graph.parameters.store import ParameterError, Parameters, ParamValue, ros2_value
from rwt_protocol.errors import RwtError
from rwt_protocol.names import MAX_NAME_LENGTH
from rwt_protocol.server.access import AccessPolicy, Family

from .protocol import (
    GetParameters,
    ParameterIn,
    ParameterOut,
    ParameterValues,
    SetParameters,
    SubscribeParameterUpdates,
    UnsubscribeParameterUpdates,
    encode_op,
)

if TYPE_CHECKING:
    from collections.abc import Awaitable

    from rwt_graph.port import GraphFront
    from rwt_protocol.server.outbox import OutFrame

    from .limits import FoxgloveLimits
    from .output import SessionOutput

__all__ = ["ParameterBridge"]

_SEP: Final = "."  # foxglove_bridge's separator of node and parameter (ROS 2)
_UNSET: Final = object()


class _SetRound:
    """One ``setParameters``: answered once every change, some made by their nodes, is done."""

    def __init__(self, request_id: str | None, names: list[str]) -> None:
        self.request_id = request_id
        self.names = names
        self.waiting = 0


class ParameterBridge:
    """Parameters of the graph as one Foxglove client reads, sets and watches them.

    Args:
        graph: the graph's core (its nodes, and the spawner of node-owned sets).
        params: the graph's parameter store.
        out: where answers and updates go.
        access: which parameters the client may use (``--params-glob``).
        limits: ``max_parameter_subscriptions``.
    """

    def __init__(
        self,
        graph: GraphFront,
        params: Parameters,
        out: SessionOutput,
        access: AccessPolicy,
        limits: FoxgloveLimits,
    ) -> None:
        self._graph = graph
        self._params = params
        self._out = out
        self._access = access
        self._limits = limits
        self._watched: dict[str, str] = {}  # store key -> the client's name
        self._changes: dict[str, object] = {}  # store key -> newest value (_UNSET: deleted)
        self._update: OutFrame | None = None  # the last push, while it waits in the queue
        self._stop = params.watch(self._changed)
        self._closed = False

    # ---- names and values ----------------------------------------------------------

    def _key(self, name: str) -> str:
        """The store's key of a client's name.

        Raises:
            ParameterError: a malformed name, or one the client may not use.
        """
        if len(name) > MAX_NAME_LENGTH:  # refused before any text echoes it whole
            raise ParameterError(f"parameter name longer than {MAX_NAME_LENGTH} characters")
        if not self._params.ros1:
            node, sep, param = name.partition(_SEP)
            if not sep:
                raise ParameterError(f"parameter name {name[:200]!r}: expected <node>.<parameter>")
            name = f"{node}:{param}"
        key = self._params.key(name)
        if not self._access.allows(Family.PARAMS, key):
            raise ParameterError(f"parameter {key} is not allowed")
        return key

    def _name(self, key: str) -> str:
        if self._params.ros1:
            return key
        node, _, param = key.partition(":")
        return f"{node}{_SEP}{param}"

    def _out_value(self, key: str, value: object) -> ParameterOut:
        name = self._name(key)
        if value is _UNSET:
            return ParameterOut(name=name)
        if isinstance(value, float):
            return ParameterOut(name=name, value=_finite(value), type="float64")
        if isinstance(value, bytes):
            return ParameterOut(
                name=name, value=base64.b64encode(value).decode("ascii"), type="byte_array"
            )
        if isinstance(value, list) and any(isinstance(item, float) for item in value):
            return ParameterOut(
                name=name, value=[_finite(float(item)) for item in value], type="float64_array"
            )
        return ParameterOut(name=name, value=value)

    # ---- ops -----------------------------------------------------------------------

    def handle(
        self,
        op: GetParameters | SetParameters | SubscribeParameterUpdates | UnsubscribeParameterUpdates,
    ) -> None:
        """Answer one parameter op of the client; problems are error statuses."""
        if isinstance(op, GetParameters):
            self.get(op)
        elif isinstance(op, SetParameters):
            self.set(op)
        elif isinstance(op, SubscribeParameterUpdates):
            self.subscribe(op)
        else:
            self.unsubscribe(op)

    def get(self, op: GetParameters) -> None:
        """Answer ``getParameters``: the values of the names that are set, with ``op.id``."""
        if op.parameterNames:
            keys = self._keys(op.parameterNames)
        else:
            keys = [key for key in self._params.names() if self._access.allows(Family.PARAMS, key)]
        self._reply(keys, op.id)

    def _keys(self, names: list[str]) -> list[str]:
        keys: list[str] = []
        for name in names:
            try:
                keys.append(self._key(name))
            except ParameterError as exc:
                self._out.error(f"getParameters: {exc.message}")
        return keys

    def _reply(self, keys: list[str], request_id: str | None) -> None:
        found = []
        for key in keys:
            value = self._params.get(key, _UNSET)
            if value is not _UNSET:
                found.append(self._out_value(key, value))
        op = ParameterValues(parameters=found, id=request_id)
        self._out.answer(encode_op(op), binary=False)

    def set(self, op: SetParameters) -> None:
        """Make each change of ``setParameters``; refusals are error statuses, one each."""
        keys: list[str] = []
        round_ = _SetRound(op.id, keys)
        for parameter in op.parameters:
            try:
                key = self._key(parameter.name)
                self._set_one(key, parameter, round_)
            except RwtError as exc:
                self._out.error(f"setParameters: {exc.message}")
                continue
            keys.append(key)
        if round_.waiting == 0:
            self._finish(round_)

    def _set_one(self, key: str, parameter: ParameterIn, round_: _SetRound) -> None:
        """Set ``key`` (or delete it: no value), in the store or on its node.

        Raises:
            ParameterError: a bad value, a node that does not exist, or what the store refuses.
        """
        value = _value_in(parameter)
        if self._params.ros1:
            if value is None:
                self._params.delete(key)
            else:
                self._params.set(key, value)
            return
        node, _, param = key.partition(":")
        if node not in self._graph.nodes.names() and node not in self._params.nodes():
            raise ParameterError(f"node {node} does not exist")
        owner = self._params.owned_by(node)
        if owner is None:
            if value is None:
                self._params.delete(key)
            else:
                self._params.set(key, value)
            return
        if value is None:
            raise ParameterError(f"{key}: the node {node} keeps its own parameters")
        spawner = self._graph.spawner
        if spawner is None:
            raise ParameterError(f"{key}: no event loop runs the node's parameter service")
        checked, _ = ros2_value(value, key)  # as the store would check it
        round_.waiting += 1
        answer = owner(param, checked)

        async def wait() -> None:
            await self._node_set(key, answer, round_)

        spawner(wait)

    async def _node_set(
        self, key: str, answer: Awaitable[tuple[bool, str]], round_: _SetRound
    ) -> None:
        try:
            successful, reason = await answer
        except Exception as exc:  # the link went away meanwhile
            successful, reason = False, str(exc)
        if not successful and not self._closed:
            self._out.error(f"setParameters: {key}: {reason}")
        round_.waiting -= 1
        if round_.waiting == 0:
            self._finish(round_)

    def _finish(self, round_: _SetRound) -> None:
        if round_.request_id is not None and not self._closed:
            self._reply(round_.names, round_.request_id)

    def subscribe(self, op: SubscribeParameterUpdates) -> None:
        """Watch these parameters: their changes are pushed (``parameterValues``, no ``id``)."""
        for name in op.parameterNames:
            try:
                key = self._key(name)
            except ParameterError as exc:
                self._out.error(f"subscribeParameterUpdates: {exc.message}")
                continue
            if key in self._watched:
                continue
            if len(self._watched) >= self._limits.max_parameter_subscriptions:
                limit = self._limits.max_parameter_subscriptions
                self._out.error(f"subscribeParameterUpdates: more than {limit} parameters")
                return
            self._watched[key] = name

    def unsubscribe(self, op: UnsubscribeParameterUpdates) -> None:
        """Stop watching these parameters (names not watched are ignored, as the SDK does)."""
        for name in op.parameterNames:
            try:
                key = self._key(name)
            except ParameterError:
                continue
            self._watched.pop(key, None)
            self._changes.pop(key, None)

    # ---- updates -------------------------------------------------------------------

    def _changed(self, key: str, value: ParamValue | None) -> None:
        if key in self._watched and not self._closed:
            self._changes[key] = _UNSET if value is None else value
            self.flush()

    def flush(self) -> None:
        """Push the merged changes, unless the last push still waits in the queue."""
        if not self._changes or (self._update is not None and self._out.unsent(self._update)):
            return
        changes, self._changes = self._changes, {}
        parameters = [self._out_value(key, value) for key, value in changes.items()]
        self._update = self._out.tracked(ParameterValues(parameters=parameters))

    def close(self) -> None:
        """The connection is gone: stop watching the store. Idempotent."""
        self._closed = True
        self._stop()
        self._watched.clear()
        self._changes.clear()


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _value_in(parameter: ParameterIn) -> object:
    """The store's value of a client's parameter; None deletes.

    Raises:
        ParameterError: a value that does not fit its ``type``, or a type not handled.
    """
    value, kind = parameter.value, parameter.type
    if kind is None or value is None:
        return value
    if kind == "float64":
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ParameterError(f"{parameter.name}: a float64 parameter needs a number")
        return float(value)
    if kind == "float64_array":
        if not isinstance(value, list) or not all(
            isinstance(item, int | float) and not isinstance(item, bool) for item in value
        ):
            raise ParameterError(f"{parameter.name}: a float64_array parameter needs numbers")
        return [float(item) for item in value]
    if kind == "byte_array":
        try:
            if isinstance(value, str):
                return base64.b64decode(value, validate=True)  # the standard alphabet, padded
        except (binascii.Error, ValueError):
            pass
        raise ParameterError(f"{parameter.name}: a byte_array parameter needs base64 text")
    raise ParameterError(f"{parameter.name}: unknown parameter type {kind[:40]!r}")
