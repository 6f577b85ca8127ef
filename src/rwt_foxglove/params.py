"""The graph's parameters for one Foxglove client, without I/O (docs/foxglove.md).

Names are foxglove_bridge's: ROS 2 ``<node>.<param>`` (``/robot.max_speed``,
the store's ``/robot:max_speed``; a node name holds no ``.``, so the first one
splits), ROS 1 the global name (``/robot/max_speed``). Values are JSON; a float
goes out with ``type: float64`` (``float64_array`` for a list of them), since
JSON writes ``1.0`` as ``1``, and comes in as a float when the client says so.
A byte array goes both ways as foxglove_bridge sends it: ``type: byte_array``
and its bytes in base64 (standard alphabet, padded).

``getParameters`` answers ``parameterValues`` with its ``id`` (none named: every
parameter the client may see), at most ``MAX_ANSWER_BYTES`` of them: the
parameters past it are left out and an error ``status`` says how many and to ask
for them by name. ``setParameters`` sets each parameter (no value deletes it)
and, with an ``id``, answers the values they have then. A refused change is an
error ``status`` naming it; the others are made. What the client sets is charged
to it, by its client id, within its share of the store (``parameters.store``,
D34). Parameters of a node that owns its own (a ROS 2 node copied by the link)
are set by that node, and the answer waits for it.
``subscribeParameterUpdates`` pushes every change made from any side (rosapi's
``set_param``, another client, the link) as ``parameterValues`` without ``id``;
a deletion is the name without a value. The bridge watches only the names the
client subscribed to (``Parameters.watch(key=...)``), so a client costs nothing
for a change of another name. Changes that come while an earlier push waits in
the queue are merged into the next one (the newest value of each), so a client
that does not read holds one. Values go out as the store holds them (shared by
every client, never copied), each encoded in the client's answer.
"""

from __future__ import annotations

import base64
import binascii
import math
from typing import TYPE_CHECKING, Final

import msgspec

from rwt_graph.parameters.store import ParameterError, Parameters, ParamValue, ros2_value
from rwt_protocol.errors import RwtError
from rwt_protocol.names import MAX_NAME_LENGTH
from rwt_protocol.runtime.access import AccessDeniedError, AccessPolicy, Family

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
    from collections.abc import Awaitable, Callable

    from rwt_graph.port import GraphFront
    from rwt_protocol.runtime.outbox import OutFrame

    from .limits import FoxgloveLimits
    from .output import SessionOutput

__all__ = ["MAX_ANSWER_BYTES", "ParameterBridge"]

_SEP: Final = "."  # foxglove_bridge's separator of node and parameter (ROS 2)
_UNSET: Final = object()

MAX_ANSWER_BYTES: Final = 4 * 1024 * 1024
"""Bytes of JSON one ``parameterValues`` answer holds at most (``getParameters``, and
``setParameters`` with an ``id``).

Parameters go in by name (every parameter: sorted); the first one that would take
the answer past it, and every one after it, is left out, and the client gets an error
status naming how many and saying to ask for them by name (docs/limits.md). The first
parameter always goes, however large: its size is bounded where it is set."""
_encode = msgspec.json.Encoder().encode


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
        out: where answers and updates go, and the session's access gate.
        access: which parameters the client may list (``--params-glob``); a name it
            asks for passes the gate (``out.require_access``).
        limits: ``max_parameter_subscriptions``.
        client_id: the connection's id in the graph, charged for what it sets.
    """

    def __init__(
        self,
        graph: GraphFront,
        params: Parameters,
        out: SessionOutput,
        access: AccessPolicy,
        limits: FoxgloveLimits,
        client_id: str | None = None,
    ) -> None:
        self._graph = graph
        self._params = params
        self._out = out
        self._access = access
        self._limits = limits
        self._client = client_id
        # store key -> the client's name, and the function that stops watching it
        self._watched: dict[str, tuple[str, Callable[[], None]]] = {}
        self._changes: dict[str, object] = {}  # store key -> newest value (_UNSET: deleted)
        self._update: OutFrame | None = None  # the last push, while it waits in the queue
        self._closed = False

    # ---- names and values ----------------------------------------------------------

    def _key(self, name: str, op: str) -> str:
        """The store's key of a client's name, through the access gate for ``op``.

        A refusal passes the session's one access gate and its log line
        (``SessionBase.require_access``, ``--params-glob``).

        Raises:
            ParameterError: a malformed name, or one the client may not use.
        """
        key = self._store_key(name)
        try:
            self._out.require_access(Family.PARAMS, key, op)
        except AccessDeniedError:
            raise ParameterError(f"parameter {key} is not allowed") from None
        return key

    def _store_key(self, name: str) -> str:
        """The store's key of a client's name (no access check).

        Raises:
            ParameterError: a malformed name.
        """
        if len(name) > MAX_NAME_LENGTH:  # refused before any text echoes it whole
            raise ParameterError(f"parameter name longer than {MAX_NAME_LENGTH} characters")
        if not self._params.ros1:
            node, sep, param = name.partition(_SEP)
            if not sep:
                raise ParameterError(f"parameter name {name[:200]!r}: expected <node>.<parameter>")
            name = f"{node}:{param}"
        return self._params.key(name)

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
        if isinstance(value, tuple):
            types = set(map(type, value))  # one C-level pass: the value is never copied here
            if types == {float}:  # JSON encodes NaN and infinities as null
                return ParameterOut(name=name, value=value, type="float64_array")
            if types == {int, float}:  # a ROS 1 list of both
                return ParameterOut(name=name, value=tuple(map(float, value)), type="float64_array")
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
            keys = self._keys(op.parameterNames, "getParameters")
        else:
            keys = [key for key in self._params.names() if self._access.allows(Family.PARAMS, key)]
        self._reply(keys, op.id, "getParameters")

    def _keys(self, names: list[str], op: str) -> list[str]:
        keys: list[str] = []
        for name in names:
            try:
                keys.append(self._key(name, op))
            except ParameterError as exc:
                self._out.error(f"getParameters: {exc.message}")
        return keys

    def _reply(self, keys: list[str], request_id: str | None, asked: str) -> None:
        """Answer the values of ``keys`` that are set, within ``MAX_ANSWER_BYTES``."""
        found: list[ParameterOut] = []
        size = 0
        left_out = 0
        for key in dict.fromkeys(keys):  # a name asked twice is answered once
            value = self._params.get(key, _UNSET)
            if value is _UNSET:
                continue
            if left_out:
                left_out += 1
                continue
            parameter = self._out_value(key, value)
            size += len(_encode(parameter)) + 1
            if found and size > MAX_ANSWER_BYTES:
                left_out = 1
                continue
            found.append(parameter)
        op = ParameterValues(parameters=found, id=request_id)
        self._out.answer(encode_op(op), binary=False)
        if left_out:
            self._out.error(
                f"{asked}: {left_out} of {len(found) + left_out} parameters left out "
                f"(an answer holds at most {MAX_ANSWER_BYTES} bytes): ask for them by name, "
                "fewer at a time"
            )

    def set(self, op: SetParameters) -> None:
        """Make each change of ``setParameters``; refusals are error statuses, one each."""
        keys: list[str] = []
        round_ = _SetRound(op.id, keys)
        for parameter in op.parameters:
            try:
                key = self._key(parameter.name, "setParameters")
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
        owner = None if self._params.ros1 else self._params.owned_by(key.partition(":")[0])
        if owner is None:
            if value is None:
                self._params.delete(key)
            else:  # the store judges the node and the client's share (D34)
                self._params.set(key, value, client=self._client)
            return
        node, _, param = key.partition(":")
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
            self._reply(round_.names, round_.request_id, "setParameters")

    def subscribe(self, op: SubscribeParameterUpdates) -> None:
        """Watch these parameters: their changes are pushed (``parameterValues``, no ``id``)."""
        for name in op.parameterNames:
            try:
                key = self._key(name, "subscribeParameterUpdates")
            except ParameterError as exc:
                self._out.error(f"subscribeParameterUpdates: {exc.message}")
                continue
            if key in self._watched:
                continue
            if len(self._watched) >= self._limits.max_parameter_subscriptions:
                limit = self._limits.max_parameter_subscriptions
                self._out.error(f"subscribeParameterUpdates: more than {limit} parameters")
                return
            self._watched[key] = (name, self._params.watch(self._changed, key))

    def unsubscribe(self, op: UnsubscribeParameterUpdates) -> None:
        """Stop watching these parameters (names not watched are ignored, as the SDK does)."""
        for name in op.parameterNames:
            try:
                key = self._store_key(name)  # only what it watches: nothing to refuse
            except ParameterError:
                continue
            watched = self._watched.pop(key, None)
            if watched is not None:
                watched[1]()
            self._changes.pop(key, None)

    @property
    def watching(self) -> bool:
        """Whether the client watches any parameter (it holds something: the idle rule)."""
        return bool(self._watched)

    # ---- updates -------------------------------------------------------------------

    def _changed(self, key: str, value: ParamValue | None) -> None:
        """A change of a watched parameter (``Parameters.watch`` of its key)."""
        if not self._closed:
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
        for _, stop in self._watched.values():
            stop()
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
    if kind == "float64_array":  # C-level passes: a large array costs no Python loop
        if not isinstance(value, list) or not set(map(type, value)) <= {int, float}:
            raise ParameterError(f"{parameter.name}: a float64_array parameter needs numbers")
        return tuple(map(float, value))
    if kind == "byte_array":
        try:
            if isinstance(value, str):
                return base64.b64decode(value, validate=True)  # the standard alphabet, padded
        except (binascii.Error, ValueError):
            pass
        raise ParameterError(f"{parameter.name}: a byte_array parameter needs base64 text")
    raise ParameterError(f"{parameter.name}: unknown parameter type {kind[:40]!r}")
