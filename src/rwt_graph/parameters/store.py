"""The in-memory parameter store (REF §7.1 get/set/has/delete_param, get_param_names).

ROS 2 parameters belong to nodes and are named ``"<node>:<param>"`` on rosapi
(``/robot:max_speed``). Their values are ``bool``, ``int`` (int64), ``float``,
``str``, ``bytes`` (a byte array) or a list of one of the others. A parameter
declared by Python code keeps its type (an ``int`` is accepted for a ``float``
parameter and a list of octets for a byte array, converted, as D9 does for
messages) and may be read-only; a parameter created by a plain ``set`` takes any
type.

ROS 1 parameters are one tree of global names (``/robot/max_speed``): a value
may also be a dict (a namespace) or a list of mixed values; ``get`` of a
namespace returns the dict; names list the leaves.

Every value handed in or out is copied, so callers cannot change the store
behind its back. Watchers hear of every change.
"""

from __future__ import annotations

import copy
import logging
import math
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, TypeAlias

from rwt_protocol.codecs.json import valid_unicode
from rwt_protocol.errors import GraphError
from rwt_protocol.names import MAX_NAME_LENGTH, name_problem, resolve_name

from ..nodes import node_name
from ..ratelog import EpisodeLog
from ..types import Dialect

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable, Mapping, Sequence

__all__ = [
    "NODE_SHARE",
    "NodeSetter",
    "ParamInfo",
    "ParamKind",
    "ParamValue",
    "ParamWatcher",
    "ParameterError",
    "ParameterNotSetError",
    "ParameterStoreFullError",
    "Parameters",
    "as_held",
    "check_param_name",
    "value_size",
]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

ParamValue: TypeAlias = (
    "bool | int | float | str | bytes | list[ParamValue] | dict[str, ParamValue]"
)
ParamWatcher: TypeAlias = "Callable[[str, ParamValue | None], None]"
"""Called with ``(name, value)`` after each change; ``value`` is None for a deletion."""
NodeSetter: TypeAlias = "Callable[[str, ParamValue], Awaitable[tuple[bool, str]]]"
"""Sets ``(param, value)`` on the node that owns the parameters, not in the store; answers
``(successful, reason)`` as the node did (``Parameters.owned_by``)."""

_INT64 = (-(2**63), 2**63 - 1)
_INT32 = (-(2**31), 2**31 - 1)  # XML-RPC integers of the ROS 1 parameter server
_MISSING = object()

NODE_SHARE = 0.25
"""The fraction of the store's parameters and of its bytes one ROS 2 node may hold.

A node copied from ROS 2 or Zenoh (``replicas``) lists whatever it
declares; without a share one node could fill the store, and every other
client's ``set_param`` would fail (docs/limits.md)."""


class ParameterError(GraphError):
    """A parameter operation was refused: bad name, bad value, type change, read-only."""


class ParameterNotSetError(ParameterError):
    """The parameter does not exist."""


class ParameterStoreFullError(ParameterError):
    """No room for it: the store is full, or the node holds its share (``NODE_SHARE``)."""


class ParamKind(StrEnum):
    """ROS 2 parameter types (``rcl_interfaces/msg/ParameterType``); EMPTY_ARRAY fits any array."""

    BOOL = "bool"
    INTEGER = "integer"
    DOUBLE = "double"
    STRING = "string"
    BYTE_ARRAY = "byte_array"
    BOOL_ARRAY = "bool_array"
    INTEGER_ARRAY = "integer_array"
    DOUBLE_ARRAY = "double_array"
    STRING_ARRAY = "string_array"
    EMPTY_ARRAY = "empty_array"


_ARRAY_OF = {
    ParamKind.BOOL: ParamKind.BOOL_ARRAY,
    ParamKind.INTEGER: ParamKind.INTEGER_ARRAY,
    ParamKind.DOUBLE: ParamKind.DOUBLE_ARRAY,
    ParamKind.STRING: ParamKind.STRING_ARRAY,
}


@dataclass(frozen=True)
class ParamInfo:
    """What a ROS 2 parameter is (``Parameters.describe``): its kind and its rules.

    ``read_only`` parameters refuse changes; a ``dynamic_typing`` one takes a value
    of any kind (every parameter a plain ``set`` created), the others keep ``kind``
    (declared by Python code, ``Parameters.declare``).
    """

    kind: ParamKind
    read_only: bool
    dynamic_typing: bool


@dataclass
class _Param:
    value: ParamValue
    kind: ParamKind
    read_only: bool = False
    fixed_type: bool = False


def _scalar_kind(value: object, what: str) -> ParamKind:
    if isinstance(value, bool):
        return ParamKind.BOOL
    if isinstance(value, int):
        if not _INT64[0] <= value <= _INT64[1]:
            raise ParameterError(f"{what}: integer {value} does not fit in int64")
        return ParamKind.INTEGER
    if isinstance(value, float):
        return ParamKind.DOUBLE
    if isinstance(value, str):
        _check_text(value, what)
        return ParamKind.STRING
    raise ParameterError(
        f"{what}: a ROS 2 parameter is a bool, int, float, str, bytes or a list of bool, "
        f"int, float or str, not {type(value).__name__}"
    )


def _check_text(value: str, what: str) -> None:
    """Refuse a string no wire form holds (JSON, UTF-8, CDR), so every reader can read it."""
    if not valid_unicode(value):
        raise ParameterError(f"{what}: a string is not valid Unicode (lone surrogate)")


def ros2_value(value: object, what: str = "value") -> tuple[ParamValue, ParamKind]:
    """Check a ROS 2 parameter value; return it (copied, ints widened in float lists) and its kind.

    ``bytes`` (or ``bytearray``) is a byte array (``ParameterType`` 5), held as ``bytes``.

    Raises:
        ParameterError: not a ROS 2 parameter value (dicts, None, nested or mixed lists,
            a list of bytes).
    """
    if isinstance(value, bytes | bytearray):
        return bytes(value), ParamKind.BYTE_ARRAY
    if not isinstance(value, list | tuple):
        return value, _scalar_kind(value, what)  # type: ignore[return-value]
    if not value:
        return [], ParamKind.EMPTY_ARRAY
    kinds = {_scalar_kind(item, f"{what}[]") for item in value}
    if kinds == {ParamKind.INTEGER, ParamKind.DOUBLE}:
        return [float(item) for item in value], ParamKind.DOUBLE_ARRAY
    if len(kinds) != 1:
        raise ParameterError(f"{what}: the items of a ROS 2 array parameter must have one type")
    return list(value), _ARRAY_OF[kinds.pop()]


def ros1_value(value: object, what: str = "value") -> ParamValue:
    """Check a ROS 1 parameter value (XML-RPC: no None, int32 integers); return a copy.

    Raises:
        ParameterError: None, a non-str dict key, an integer outside int32, another type.
    """
    if isinstance(value, str):
        _check_text(value, what)
        return value
    if isinstance(value, bool | float):
        return value
    if isinstance(value, int):
        if not _INT32[0] <= value <= _INT32[1]:
            raise ParameterError(f"{what}: integer {value} does not fit in int32")
        return value
    if isinstance(value, list | tuple):
        return [ros1_value(item, f"{what}[{i}]") for i, item in enumerate(value)]
    if isinstance(value, dict):
        out: dict[str, ParamValue] = {}
        for key, item in value.items():
            if not isinstance(key, str) or not key or "/" in key:
                raise ParameterError(f"{what}: namespace keys are non-empty names, got {key!r}")
            _check_text(key, what)
            out[key] = ros1_value(item, f"{what}.{key}")
        return out
    raise ParameterError(f"{what}: a ROS 1 parameter cannot be {type(value).__name__}")


def as_held(held: object, value: ParamValue) -> ParamValue:
    """``value`` as bytes when ``held`` is a byte array and ``value`` a list of octets.

    JSON has no bytes: rosapi's ``get_param`` answers a byte array as its octets
    (``to_json_safe``), so a client writing back what it read sends a list of ints
    0-255; for a byte-array parameter that is the same byte array (D9 reads a
    ``byte[]`` field from JSON the same way). Any other value is returned as it is.
    """
    if not isinstance(held, bytes) or not isinstance(value, list):
        return value
    octets = [item for item in value if type(item) is int and 0 <= item <= 255]
    return bytes(octets) if len(octets) == len(value) else value


def _fit(param: _Param, value: ParamValue, kind: ParamKind, name: str) -> ParamValue:
    """The value to store in a parameter whose type is fixed (declared)."""
    if param.kind is ParamKind.BYTE_ARRAY and isinstance(octets := as_held(b"", value), bytes):
        return octets  # the byte array itself, or a list of octets (or an empty list)
    if kind is param.kind or (param.kind is ParamKind.EMPTY_ARRAY and kind.endswith("array")):
        return value
    if param.kind is ParamKind.DOUBLE and kind is ParamKind.INTEGER:
        return float(value)  # type: ignore[arg-type]
    if param.kind is ParamKind.DOUBLE_ARRAY and kind is ParamKind.INTEGER_ARRAY:
        return [float(item) for item in value]  # type: ignore[union-attr, arg-type]
    if kind is ParamKind.EMPTY_ARRAY and param.kind.endswith("array"):
        return []
    raise ParameterError(f"parameter {name} has type {param.kind}, not {kind}")


def _changed(entry: _Param | None, value: object, full: str) -> _Param:
    """The entry ``full`` has once set to ``value`` (``entry``: the one it has, if any).

    Raises:
        ParameterError: a bad value, a read-only parameter, or a type change of a
            declared one.
    """
    stored, kind = ros2_value(value, full)
    if entry is None:
        return _Param(stored, kind)
    if entry.read_only:
        raise ParameterError(f"parameter {full} is read-only")
    if entry.fixed_type:
        return _Param(_fit(entry, stored, kind, full), entry.kind, fixed_type=True)
    return _Param(stored, kind)


def _planned(entry: _Param | None, name: str, value: object, full: str) -> _Param | None:
    """The entry ``name`` (``full``, now ``entry``) has once set to ``value``; None deletes.

    Raises:
        ParameterNotSetError: a deletion of a parameter that is not set.
        ParameterError: what ``set`` or ``delete`` would refuse.
    """
    if value is not None:
        check_param_name(name, ros1=False)
        return _changed(entry, value, full)
    if entry is None:
        raise ParameterNotSetError(f"parameter {full} is not set")
    if entry.read_only:
        raise ParameterError(f"parameter {full} is read-only")
    return None


def split_ros2_name(name: str) -> tuple[str, str]:
    """Split ``"<node>:<param>"`` (REF §7.1); the node becomes absolute.

    Raises:
        ParameterError: no ``:``, an empty part, more than one ``:``, a bad node name.
    """
    node, sep, param = name.partition(":")
    if not sep or not node or not param or ":" in param:
        raise ParameterError(f"parameter name {name!r}: expected <node>:<parameter>")
    try:
        return node_name(node), param
    except GraphError as exc:
        raise ParameterError(f"parameter name {name!r}: {exc.message}") from None


def check_param_name(name: str, *, ros1: bool) -> None:
    """Check the name of a parameter being created, so that listing it never fails.

    ROS 1 names are graph resource names (``names.name_problem``) or ``/``; a ROS 2
    ``<node>:<param>`` name is checked by ``split_ros2_name`` (node part) and here
    (the parameter part, which ROS 2 lets hold ``.`` and more): at most
    ``MAX_NAME_LENGTH`` characters of valid Unicode (docs/limits.md).

    Raises:
        ParameterError: the name breaks these rules.
    """
    root = ros1 and resolve_name(name) == "/"  # ROS 1: setting "/" sets the whole tree
    problem = name_problem(name) if ros1 and not root else None
    if problem is None and len(name) > MAX_NAME_LENGTH:
        problem = f"name longer than {MAX_NAME_LENGTH} characters"
    if problem is None and not valid_unicode(name):
        problem = "name is not valid Unicode (lone surrogate)"
    if problem is not None:
        raise ParameterError(f"parameter name: {problem}")


def to_json_safe(value: ParamValue) -> object:
    """``value`` with non-finite floats as None and bytes as a list of octets, for JSON text (D10).

    A byte array becomes its octets (ints 0-255), as a ``byte[]`` field of a
    message goes out in JSON (docs/ros2.md, "Parameters").
    """
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, bytes):
        return list(value)
    if isinstance(value, list):
        return [to_json_safe(item) for item in value]
    if isinstance(value, dict):
        return {key: to_json_safe(item) for key, item in value.items()}
    return value


class Parameters:
    """The parameters of one graph, in the dialect's naming.

    Args:
        dialect: ROS 2 names ``"<node>:<param>"``; ROS 1 global names.
        max_params: most parameters (ROS 1: leaves) the store holds; a ``set`` that
            would go over is refused, so a client cannot grow it without bound.
        max_bytes: most bytes all values may hold together (strings count their
            UTF-8 bytes, byte arrays their length, numbers and bools 8); a ``set``
            that would go over is refused (docs/limits.md).
        node_share: the fraction of ``max_params`` and of ``max_bytes`` one ROS 2
            node may hold (``max_node_params``, ``max_node_bytes``; at least one
            parameter and byte), so one node cannot fill the store; 1 lets a node
            hold all of it. ROS 1 names have no nodes and no share.
    """

    def __init__(
        self,
        dialect: Dialect = Dialect.ROS2,
        *,
        max_params: int = 10_000,
        max_bytes: int = 64 * 1024 * 1024,
        node_share: float = NODE_SHARE,
    ) -> None:
        self.dialect = dialect
        self.max_params = max_params
        self.max_bytes = max_bytes
        self.max_node_params = max(1, int(max_params * node_share))
        self.max_node_bytes = max(1, int(max_bytes * node_share))
        self._bytes = 0  # the values' sizes (``value_size``), kept up to date
        self._nodes: dict[str, dict[str, _Param]] = {}  # ROS 2
        self._node_bytes: dict[str, int] = {}  # ROS 2: each node's part of ``_bytes``
        self._count = 0  # ROS 2 parameters held: a new one checks room without a walk
        self._tree: dict[str, ParamValue] = {}  # ROS 1
        self._watchers: list[ParamWatcher] = []
        self._owners: dict[str, NodeSetter] = {}  # ROS 2 nodes whose values are copies

    @property
    def ros1(self) -> bool:
        """Whether names are ROS 1 global names."""
        return self.dialect is Dialect.ROS1

    # ---- public API ------------------------------------------------------------------

    def declare(
        self,
        node: str,
        values: Mapping[str, object],
        *,
        read_only: bool = False,
        dynamic_typing: bool = False,
    ) -> None:
        """Declare parameters of ``node`` with their initial values.

        In ROS 2 each keeps its type unless ``dynamic_typing``, and ``read_only``
        ones refuse ``set`` and ``delete`` (from clients and from Python). In ROS 1
        this sets ``<node>/<name>`` for each entry (types and read-only do not apply).

        Raises:
            ParameterStoreFullError: no room (``set``); the parameters before it
                are declared.
            ParameterError: a bad node or parameter name, or a bad value.
        """
        if self.ros1:
            for name, value in values.items():
                self.set(f"{node_name(node)}/{name}", value)
            return
        for name, value in values.items():
            full = f"{node}:{name}"
            node_key, param = split_ros2_name(full)
            stored, kind = ros2_value(value, full)
            self._check_room(node_key, param)
            old = self._nodes.get(node_key, {}).get(param)
            self._grow(stored, None if old is None else old.value, node_key)
            entry = _Param(stored, kind, read_only=read_only, fixed_type=not dynamic_typing)
            self._nodes.setdefault(node_key, {})[param] = entry
            if old is None:
                self._count += 1
            self._notify(f"{node_key}:{param}", stored)

    def set(self, name: str, value: object) -> None:
        """Set a parameter, creating it (and, in ROS 2, its node's entry) if needed.

        Raises:
            ParameterStoreFullError: the store is full, or the ROS 2 node holds
                its share of it (``max_node_params``, ``max_node_bytes``).
            ParameterError: bad name or value, a type change of a declared ROS 2
                parameter, a read-only parameter.
        """
        check_param_name(name, ros1=self.ros1)
        if self.ros1:
            key = resolve_name(name)
            stored = ros1_value(value, key)
            self._tree_set(key, stored)
            self._notify(key, stored)
            return
        node, param = split_ros2_name(name)
        full = f"{node}:{param}"
        entry = self._nodes.get(node, {}).get(param)
        new = _changed(entry, value, full)
        if entry is None:
            self._check_room(node, param)
        self._grow(new.value, None if entry is None else entry.value, node)
        self._nodes.setdefault(node, {})[param] = new
        if entry is None:
            self._count += 1
        self._notify(full, new.value)

    def set_all(self, changes: Sequence[tuple[str, object]]) -> None:
        """Set ROS 2 parameters all at once, or none: ``(name, value)`` pairs, None deletes.

        Each change is judged as ``set`` (a value) or ``delete`` (None) would judge
        it, in order (a later change of the same name sees the earlier one), and the
        room left in the store and in each node's share counts them all; watchers
        hear of the changes only once every one of them is made
        (``set_parameters_atomically``, docs/ros2.md).

        Raises:
            ParameterError: the first change refused (the message names it); nothing
                was changed. ROS 1 stores have no atomic set.
        """
        if self.ros1:
            raise ParameterError("ROS 1 parameters have no atomic set")
        plan: dict[tuple[str, str], _Param | None] = {}
        count, size = self._count, self._bytes
        counts: dict[str, int] = {}  # node -> parameters it will hold
        sizes: dict[str, int] = {}  # node -> bytes it will hold
        for name, value in changes:
            node, param = split_ros2_name(name)
            key = (node, param)
            old = plan[key] if key in plan else self._nodes.get(node, {}).get(param)
            new = _planned(old, name, value, f"{node}:{param}")
            added = (new is not None) - (old is not None)
            grown = (0 if new is None else value_size(new.value)) - (
                0 if old is None else value_size(old.value)
            )
            count += added
            size += grown
            counts[node] = counts.get(node, len(self._nodes.get(node, ()))) + added
            sizes[node] = sizes.get(node, self._node_bytes.get(node, 0)) + grown
            self._check_counts(count, node, counts[node])
            plan[key] = new
        self._check_sizes(size, sizes)
        for (node, param), new in plan.items():
            params = self._nodes.setdefault(node, {})
            if new is None:
                params.pop(param, None)
                if not params:
                    del self._nodes[node]
            else:
                params[param] = new
        for node, node_size in sizes.items():
            if node in self._nodes:
                self._node_bytes[node] = node_size
            else:
                self._node_bytes.pop(node, None)
        self._count, self._bytes = count, size
        for (node, param), new in plan.items():
            self._notify(f"{node}:{param}", None if new is None else new.value)

    def _check_counts(self, count: int, node: str, held: int) -> None:
        """Refuse a plan past which the store holds ``count``, ``node`` ``held`` parameters.

        Raises:
            ParameterStoreFullError: either is over its bound and more than now.
        """
        if count > self.max_params and count > self._count:
            raise ParameterStoreFullError(
                f"the parameter store is full ({self.max_params} parameters)"
            )
        if held > self.max_node_params and held > len(self._nodes.get(node, ())):
            raise ParameterStoreFullError(
                self._share_full(node, f"{self.max_node_params} parameters")
            )

    def _check_sizes(self, size: int, sizes: Mapping[str, int]) -> None:
        """Refuse a plan past which the values hold ``size`` bytes, each node its ``sizes``.

        Raises:
            ParameterStoreFullError: one is over its bound and more than now.
        """
        if size > self.max_bytes and size > self._bytes:
            raise ParameterStoreFullError(f"the parameter store is full ({self.max_bytes} bytes)")
        for node, held in sizes.items():
            if held > self.max_node_bytes and held > self._node_bytes.get(node, 0):
                raise ParameterStoreFullError(
                    self._share_full(node, f"{self.max_node_bytes} bytes")
                )

    def describe(self, name: str) -> ParamInfo | None:
        """What kind of ROS 2 parameter ``name`` is; None if it is not set.

        Raises:
            ParameterError: a malformed name, or a ROS 1 store (no kinds there).
        """
        if self.ros1:
            raise ParameterError("ROS 1 parameters have no descriptors")
        node, param = split_ros2_name(name)
        entry = self._nodes.get(node, {}).get(param)
        if entry is None:
            return None
        return ParamInfo(entry.kind, read_only=entry.read_only, dynamic_typing=not entry.fixed_type)

    def get(self, name: str, default: object = _MISSING) -> ParamValue:
        """A copy of the parameter's value (ROS 1: a namespace gives a dict).

        Raises:
            ParameterNotSetError: it does not exist and no ``default`` was given.
            ParameterError: a malformed name.
        """
        found = self._lookup(name)
        if found is _MISSING:
            if default is _MISSING:
                raise ParameterNotSetError(f"parameter {name} is not set")
            return default  # type: ignore[return-value]
        return copy.deepcopy(found)  # type: ignore[return-value]

    def has(self, name: str) -> bool:
        """Whether the parameter (ROS 1: or namespace) exists; False for a malformed name."""
        try:
            return self._lookup(name) is not _MISSING
        except ParameterError:
            return False

    def delete(self, name: str) -> None:
        """Remove a parameter (ROS 1: or a whole namespace).

        Raises:
            ParameterNotSetError: it does not exist.
            ParameterError: a malformed name, or a read-only ROS 2 parameter.
        """
        if self.ros1:
            key = resolve_name(name)
            self._tree_delete(key)
            self._notify(key, None)
            return
        node, param = split_ros2_name(name)
        params = self._nodes.get(node, {})
        entry = params.get(param)
        if entry is None:
            raise ParameterNotSetError(f"parameter {node}:{param} is not set")
        if entry.read_only:
            raise ParameterError(f"parameter {node}:{param} is read-only")
        size = value_size(entry.value)
        self._bytes -= size
        self._node_bytes[node] -= size
        del params[param]
        self._count -= 1
        if not params:
            del self._nodes[node]
            del self._node_bytes[node]
        self._notify(f"{node}:{param}", None)

    def key(self, name: str) -> str:
        """The name as the store spells it: ``/node:param`` (ROS 2) or absolute (ROS 1).

        Raises:
            ParameterError: a malformed ROS 2 name.
        """
        if self.ros1:
            return resolve_name(name)
        node, param = split_ros2_name(name)
        return f"{node}:{param}"

    def names(self) -> list[str]:
        """Every parameter name, sorted: ``/node:param`` (ROS 2) or leaf global names (ROS 1)."""
        if self.ros1:
            return sorted(_leaves(self._tree, ""))
        return sorted(f"{node}:{param}" for node, params in self._nodes.items() for param in params)

    def nodes(self) -> frozenset[str]:
        """The ROS 2 nodes that have parameters (none in ROS 1)."""
        return frozenset(self._nodes)

    def room(self, node: str) -> int:
        """How many more parameters ROS 2 ``node`` may have now: the store's room, within its share.

        Raises:
            ParameterError: a bad node name, or a ROS 1 store (no nodes there).
        """
        key = self._node_key(node)
        held = len(self._nodes.get(key, ()))
        return max(0, min(self.max_params - self._count, self.max_node_params - held))

    def room_problem(self, node: str) -> str | None:
        """Why a new parameter of ROS 2 ``node`` would be refused for room now; None if it fits.

        Raises:
            ParameterError: a bad node name, or a ROS 1 store (no nodes there).
        """
        return self._room_problem(self._node_key(node))

    def search(self, name: str) -> str:
        """ROS 1 ``search_param`` from the root namespace: the global name if set, else ``""``."""
        key = resolve_name(name)
        return key if self.has(key) else ""

    def watch(self, watcher: ParamWatcher) -> Callable[[], None]:
        """Call ``watcher(name, value)`` after every change; returns a function that stops it."""
        self._watchers.append(watcher)

        def stop() -> None:
            if watcher in self._watchers:
                self._watchers.remove(watcher)

        return stop

    def own(self, node: str, setter: NodeSetter | None) -> None:
        """Say that ``node``'s parameters here are copies that ``setter`` changes on the node.

        A link that copies another node's parameters (``replicas``) owns them:
        rosapi's ``set_param`` then asks the node and answers what it answered. None
        gives the node's parameters back to the store.
        """
        if setter is None:
            self._owners.pop(node, None)
        else:
            self._owners[node] = setter

    def owned_by(self, node: str) -> NodeSetter | None:
        """The setter of the node that owns ``node``'s parameters, or None (``own``)."""
        return self._owners.get(node)

    # ---- internals ---------------------------------------------------------------

    def _notify(self, name: str, value: ParamValue | None) -> None:
        for watcher in list(self._watchers):
            try:
                watcher(name, copy.deepcopy(value))
            except Exception:  # one broken watcher must not stop the others
                _episodes.log(
                    logging.ERROR,
                    "watcher_failed",
                    "parameter watcher failed on %s",
                    name,
                    exc_info=True,
                )

    def _grow(self, new: ParamValue, old: ParamValue | None, node: str | None = None) -> None:
        """Account for ``old`` becoming ``new`` (a parameter of ROS 2 ``node``, if given).

        Raises:
            ParameterStoreFullError: the values would hold more than ``max_bytes``,
                or ``node``'s more than ``max_node_bytes``; nothing is counted.
        """
        grown = value_size(new) - (0 if old is None else value_size(old))
        total = self._bytes + grown
        if total > self.max_bytes and grown > 0:
            raise ParameterStoreFullError(f"the parameter store is full ({self.max_bytes} bytes)")
        if node is not None:
            mine = self._node_bytes.get(node, 0) + grown
            if mine > self.max_node_bytes and grown > 0:
                raise ParameterStoreFullError(
                    self._share_full(node, f"{self.max_node_bytes} bytes")
                )
            self._node_bytes[node] = mine
        self._bytes = total

    def _check_room(self, node: str, param: str) -> None:
        if param in self._nodes.get(node, {}):
            return
        problem = self._room_problem(node)
        if problem is not None:
            raise ParameterStoreFullError(problem)

    def _room_problem(self, node: str) -> str | None:
        if self._count >= self.max_params:
            return f"the parameter store is full ({self.max_params} parameters)"
        if len(self._nodes.get(node, ())) >= self.max_node_params:
            return self._share_full(node, f"{self.max_node_params} parameters")
        return None

    @staticmethod
    def _share_full(node: str, share: str) -> str:
        return f"node {node} holds its share of the parameter store ({share})"

    def _node_key(self, node: str) -> str:
        if self.ros1:
            raise ParameterError("ROS 1 parameters have no nodes")
        try:
            return node_name(node)
        except GraphError as exc:
            raise ParameterError(f"node name {node!r}: {exc.message}") from None

    def _lookup(self, name: str) -> object:
        if self.ros1:
            node: object = self._tree
            for token in _tokens(resolve_name(name)):
                if not isinstance(node, dict) or token not in node:
                    return _MISSING
                node = node[token]
            return node
        node_key, param = split_ros2_name(name)
        entry = self._nodes.get(node_key, {}).get(param)
        return _MISSING if entry is None else entry.value

    def _tree_set(self, key: str, value: ParamValue) -> None:
        tokens = _tokens(key)
        if not tokens:
            if not isinstance(value, dict):
                raise ParameterError("the root namespace / can only be set to a dict")
            self._check_leaves(_count(value) - _count(self._tree))
            self._grow(value, self._tree)
            self._tree = value
            return
        old = self._lookup(key)
        self._check_leaves(_count(value) - (0 if old is _MISSING else _count(old)))
        self._grow(value, None if old is _MISSING else old)  # type: ignore[arg-type]
        node = self._tree
        for token in tokens[:-1]:
            child = node.get(token)
            if not isinstance(child, dict):  # a value on the way becomes a namespace
                child = node[token] = {}
            node = child
        node[tokens[-1]] = value

    def _check_leaves(self, added: int) -> None:
        if added > 0 and _count(self._tree) + added > self.max_params:
            raise ParameterStoreFullError(
                f"the parameter store is full ({self.max_params} parameters)"
            )

    def _tree_delete(self, key: str) -> None:
        tokens = _tokens(key)
        if not tokens:
            self._tree, self._bytes = {}, 0
            return
        node: object = self._tree
        for token in tokens[:-1]:
            node = node.get(token) if isinstance(node, dict) else None
        if not isinstance(node, dict) or tokens[-1] not in node:
            raise ParameterNotSetError(f"parameter {key} is not set")
        self._bytes -= value_size(node[tokens[-1]])
        del node[tokens[-1]]


def _tokens(key: str) -> list[str]:
    return [token for token in key.split("/") if token]


def _leaves(tree: Mapping[str, ParamValue], prefix: str) -> list[str]:
    found: list[str] = []
    for key, value in tree.items():
        if isinstance(value, dict):
            found += _leaves(value, f"{prefix}/{key}")
        else:
            found.append(f"{prefix}/{key}")
    return found


def value_size(value: object) -> int:
    """Count the bytes a parameter value holds against ``Parameters.max_bytes``.

    UTF-8 bytes of strings and keys, the length of a byte array, 8 per number or
    bool, summed over lists and dicts.
    """
    if isinstance(value, str):
        return len(value) if value.isascii() else len(value.encode("utf-8", "surrogatepass"))
    if isinstance(value, bytes):
        return len(value)
    if isinstance(value, dict):
        return sum(value_size(key) + value_size(item) for key, item in value.items())
    if isinstance(value, list):
        return sum(value_size(item) for item in value)
    return 8


def _count(value: object) -> int:
    if isinstance(value, dict):
        return sum(_count(item) for item in value.values())
    return 1
