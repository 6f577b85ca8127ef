"""The in-memory parameter store (REF §7.1 get/set/has/delete_param, get_param_names).

ROS 2 parameters belong to nodes and are named ``"<node>:<param>"`` on rosapi
(``/robot:max_speed``). Their values are ``bool``, ``int`` (int64), ``float``,
``str``, ``bytes`` (a byte array) or a tuple of one of the others (a list given
is held as a tuple). A parameter declared by Python code keeps its type (an
``int`` is accepted for a ``float`` parameter and a list of octets for a byte
array, converted, as D9 does for messages) and may be read-only; a parameter
created by a plain ``set`` takes any type.

ROS 1 parameters are one tree of global names (``/robot/max_speed``): a value
may also be a namespace (a dict, held as ``FrozenNamespace``) or a tuple of mixed
values; ``get`` of a namespace returns it; names list the leaves (``tree``).

Values are checked once, when set, and then held frozen: ``get`` and every
watcher get the held object itself, never a copy, and nobody can change it
behind the store's back (``values``). A watcher of one name (``watch(key=...)``)
costs nothing for a change of another.

A client (a rosbridge or Foxglove connection) that sets a parameter is charged
for it, within its share of the store (``CLIENT_SHARE``, ``shares``); it may
create parameters only on a node that exists and is neither the server's
(``SERVER_NODES``) nor another live client's. When it disconnects, the
parameters of its own node go with the node, and the others it created outlive
it, within one share for all that clients left behind (D34, docs/limits.md).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeAlias

from rwt_protocol.codecs.json import valid_unicode
from rwt_protocol.errors import GraphError
from rwt_protocol.names import MAX_NAME_LENGTH, name_problem, resolve_name

from ..nodes import CLIENT_NODE_PREFIX, SERVER_NODES, node_name
from ..ratelog import EpisodeLog
from ..types import Dialect
from .shares import Shares
from .tree import MISSING, Ros1Tree
from .values import (
    FrozenNamespace,
    ParameterError,
    ParameterNotSetError,
    ParameterStoreFullError,
    ParamKind,
    ParamValue,
    as_held,
    json_text,
    ros1_value,
    ros2_value,
    to_json_safe,
    value_size,
)

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable, Mapping, Sequence

    from rwt_protocol.ports import ClientId

    from ..nodes import Nodes

__all__ = [
    "CLIENT_SHARE",
    "NODE_SHARE",
    "SERVER_NODES",
    "FrozenNamespace",
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
    "json_text",
    "ros1_value",
    "ros2_value",
    "to_json_safe",
    "value_size",
]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

ParamWatcher: TypeAlias = "Callable[[str, ParamValue | None], None]"
"""Called with ``(name, value)`` after each change; ``value`` is None for a deletion.
``value`` is the held (frozen) value itself, shared with every other reader."""
NodeSetter: TypeAlias = "Callable[[str, ParamValue], Awaitable[tuple[bool, str]]]"
"""Sets ``(param, value)`` on the node that owns the parameters, not in the store; answers
``(successful, reason)`` as the node did (``Parameters.owned_by``)."""

NODE_SHARE = 0.25
"""The fraction of the store's parameters and of its bytes one ROS 2 node may hold.

A node copied from ROS 2 or Zenoh (``replicas``) lists whatever it
declares; without a share one node could fill the store, and every other
client's ``set_param`` would fail (docs/limits.md)."""

CLIENT_SHARE = 0.125
"""The fraction of the store's parameters and of its bytes one client may be charged.

A client (a rosbridge or Foxglove connection, by its id in the graph) is charged
for the parameters it set, on any node; so are, together, the parameters clients
that disconnected left behind (``shares``). Without it one client could fill the
store on every node it can name, and every other client's ``set_param`` would
fail (docs/limits.md)."""


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


@dataclass(slots=True)
class _Param:
    value: ParamValue
    kind: ParamKind
    size: int  # value_size(value), counted once
    read_only: bool = False
    fixed_type: bool = False


def _fit(param: _Param, value: ParamValue, kind: ParamKind, name: str) -> ParamValue:
    """The value to store in a parameter whose type is fixed (declared)."""
    if param.kind is ParamKind.BYTE_ARRAY and isinstance(octets := as_held(b"", value), bytes):
        return octets  # the byte array itself, or a tuple of octets (or an empty one)
    if kind is param.kind or (param.kind is ParamKind.EMPTY_ARRAY and kind.endswith("array")):
        return value
    if param.kind is ParamKind.DOUBLE and kind is ParamKind.INTEGER:
        return float(value)  # type: ignore[arg-type]
    if param.kind is ParamKind.DOUBLE_ARRAY and kind is ParamKind.INTEGER_ARRAY:
        return tuple(map(float, value))  # type: ignore[arg-type]
    if kind is ParamKind.EMPTY_ARRAY and param.kind.endswith("array"):
        return ()
    raise ParameterError(f"parameter {name} has type {param.kind}, not {kind}")


_NUMBER_ARRAYS = frozenset({ParamKind.BOOL_ARRAY, ParamKind.INTEGER_ARRAY, ParamKind.DOUBLE_ARRAY})


def _entry(value: ParamValue, kind: ParamKind, **rules: bool) -> _Param:
    """A held entry; an array of numbers is sized by its length (8 bytes an item)."""
    size = 8 * len(value) if kind in _NUMBER_ARRAYS else value_size(value)  # type: ignore[arg-type]
    return _Param(value, kind, size, **rules)


def _changed(entry: _Param | None, value: object, full: str) -> _Param:
    """The entry ``full`` has once set to ``value`` (``entry``: the one it has, if any).

    Raises:
        ParameterError: a bad value, a read-only parameter, or a type change of a
            declared one.
    """
    stored, kind = ros2_value(value, full)
    if entry is None:
        return _entry(stored, kind)
    if entry.read_only:
        raise ParameterError(f"parameter {full} is read-only")
    if entry.fixed_type:
        return _entry(_fit(entry, stored, kind, full), entry.kind, fixed_type=True)
    return _entry(stored, kind)


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


class Parameters:
    """The parameters of one graph, in the dialect's naming.

    Args:
        dialect: ROS 2 names ``"<node>:<param>"``; ROS 1 global names.
        max_params: most parameters (ROS 1: leaves and empty namespaces) the store
            holds; a ``set`` that would go over is refused, so a client cannot grow
            it without bound.
        max_bytes: most bytes all values may hold together (strings count their
            UTF-8 bytes, byte arrays their length, a number or bool 8; ROS 1 leaves
            also their last name token); a ``set`` that would go over is refused
            (docs/limits.md).
        node_share: the fraction of ``max_params`` and of ``max_bytes`` one ROS 2
            node may hold (``max_node_params``, ``max_node_bytes``; at least one
            parameter and byte), so one node cannot fill the store; 1 lets a node
            hold all of it. ROS 1 names have no nodes and no share.
        client_share: the fraction one client may be charged (``max_client_params``,
            ``max_client_bytes``; ``CLIENT_SHARE``, at least one of each).
        nodes: the graph's nodes (``Graph.nodes``): with them, a client may create
            parameters only on a node that exists and is neither the server's nor
            another client's, and what it set is released when it leaves (D34);
            without them only the client's share applies.
    """

    def __init__(
        self,
        dialect: Dialect = Dialect.ROS2,
        *,
        max_params: int = 10_000,
        max_bytes: int = 64 * 1024 * 1024,
        node_share: float = NODE_SHARE,
        client_share: float = CLIENT_SHARE,
        nodes: Nodes | None = None,
    ) -> None:
        self.dialect = dialect
        self.max_params = max_params
        self.max_bytes = max_bytes
        self.max_node_params = max(1, int(max_params * node_share))
        self.max_node_bytes = max(1, int(max_bytes * node_share))
        self.max_client_params = max(1, int(max_params * client_share))
        self.max_client_bytes = max(1, int(max_bytes * client_share))
        self._bytes = 0  # ROS 2: the values' sizes (``value_size``), kept up to date
        self._nodes: dict[str, dict[str, _Param]] = {}  # ROS 2
        self._node_bytes: dict[str, int] = {}  # ROS 2: each node's part of ``_bytes``
        self._count = 0  # ROS 2 parameters held: a new one checks room without a walk
        self._tree = Ros1Tree()  # ROS 1
        self._watchers: list[ParamWatcher] = []
        self._keyed: dict[str, list[ParamWatcher]] = {}  # key -> watchers of it alone
        self._owners: dict[str, NodeSetter] = {}  # ROS 2 nodes whose values are copies
        self._shares = Shares(self.max_client_params, self.max_client_bytes)
        self._graph_nodes = nodes
        if nodes is not None:
            nodes.on_forget.append(self._forgotten)

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
            entry = _entry(stored, kind, read_only=read_only, fixed_type=not dynamic_typing)
            self._put(node_key, param, entry, None)

    def set(self, name: str, value: object, *, client: ClientId | None = None) -> None:
        """Set a parameter, creating it (and, in ROS 2, its node's entry) if needed.

        Args:
            name: ``<node>:<param>`` (ROS 2) or a global name (ROS 1).
            value: the value, checked and held frozen (a list as a tuple).
            client: the client that asks (a connection's id): charged for it within
                its share, and (ROS 2) refused a parameter it would create on a node
                that does not exist, is the server's or another live client's. None:
                in-process code or a link, charged to nobody.

        Raises:
            ParameterStoreFullError: the store is full, the ROS 2 node holds its
                share of it (``max_node_params``, ``max_node_bytes``), or the
                client its own (``max_client_params``, ``max_client_bytes``).
            ParameterError: bad name or value, a type change of a declared ROS 2
                parameter, a read-only parameter, a node the client may not use.
        """
        check_param_name(name, ros1=self.ros1)
        if self.ros1:
            self._ros1_set(resolve_name(name), value, client)
            return
        node, param = split_ros2_name(name)
        full = f"{node}:{param}"
        entry = self._nodes.get(node, {}).get(param)
        new = _changed(entry, value, full)
        if entry is None and client is not None:
            self._check_creator(client, node)
        self._put(node, param, new, client)

    def _put(self, node: str, param: str, new: _Param, client: ClientId | None) -> None:
        """Make ``node:param`` hold ``new``, set by ``client`` (None: in-process, a link).

        Raises:
            ParameterStoreFullError: no room in the store, the node's or the client's share.
        """
        key = f"{node}:{param}"
        entry = self._nodes.get(node, {}).get(param)
        if entry is None:
            self._check_room(node, param)
        if client is not None:
            self._shares.check(client, {key: new.size})
        self._grow(new.size, 0 if entry is None else entry.size, node)
        self._nodes.setdefault(node, {})[param] = new
        if entry is None:
            self._count += 1
        self._shares.charge(key, client, new.size)
        self._notify(key, new.value)

    def set_all(
        self, changes: Sequence[tuple[str, object]], *, client: ClientId | None = None
    ) -> None:
        """Set ROS 2 parameters all at once, or none: ``(name, value)`` pairs, None deletes.

        Each change is judged as ``set`` (a value) or ``delete`` (None) would judge
        it, in order (a later change of the same name sees the earlier one), and the
        room left in the store and in each node's share counts them all; watchers
        hear of the changes only once every one of them is made
        (``set_parameters_atomically``, docs/ros2.md). ``client``: the client that
        asks, judged and charged as ``set`` judges and charges it (D34); None (a
        link, in-process code): the parameters changed are charged to nobody.

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
            if client is not None and old is None and new is not None:
                self._check_creator(client, node)
            added = (new is not None) - (old is not None)
            grown = (0 if new is None else new.size) - (0 if old is None else old.size)
            count += added
            size += grown
            counts[node] = counts.get(node, len(self._nodes.get(node, ()))) + added
            sizes[node] = sizes.get(node, self._node_bytes.get(node, 0)) + grown
            self._check_counts(count, node, counts[node])
            plan[key] = new
        self._check_sizes(size, sizes)
        if client is not None:
            self._shares.check(
                client,
                {f"{n}:{p}": None if new is None else new.size for (n, p), new in plan.items()},
            )
        self._apply_plan(plan, sizes, client)
        self._count, self._bytes = count, size
        for (node, param), new in plan.items():
            self._notify(f"{node}:{param}", None if new is None else new.value)

    def _apply_plan(
        self,
        plan: dict[tuple[str, str], _Param | None],
        sizes: dict[str, int],
        client: ClientId | None,
    ) -> None:
        for (node, param), new in plan.items():
            params = self._nodes.setdefault(node, {})
            if new is None:
                params.pop(param, None)
                if not params:
                    del self._nodes[node]
                self._shares.release(f"{node}:{param}")
            else:
                params[param] = new
                self._shares.charge(f"{node}:{param}", client, new.size)
        for node, node_size in sizes.items():
            if node in self._nodes:
                self._node_bytes[node] = node_size
            else:
                self._node_bytes.pop(node, None)

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

    def get(self, name: str, default: object = MISSING) -> ParamValue:
        """The parameter's value, the held (frozen) object itself (ROS 1: a namespace).

        Raises:
            ParameterNotSetError: it does not exist and no ``default`` was given.
            ParameterError: a malformed name.
        """
        found = self._lookup(name)
        if found is MISSING:
            if default is MISSING:
                raise ParameterNotSetError(f"parameter {name} is not set")
            return default  # type: ignore[return-value]
        return found  # type: ignore[return-value]

    def has(self, name: str) -> bool:
        """Whether the parameter (ROS 1: or namespace) exists; False for a malformed name."""
        try:
            return self._lookup(name) is not MISSING
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
            for removed in self._tree.delete(key):
                self._shares.release(removed)
            self._notify(key, None)
            return
        node, param = split_ros2_name(name)
        entry = self._nodes.get(node, {}).get(param)
        if entry is None:
            raise ParameterNotSetError(f"parameter {node}:{param} is not set")
        if entry.read_only:
            raise ParameterError(f"parameter {node}:{param} is read-only")
        self._remove(node, param)

    def _remove(self, node: str, param: str) -> None:
        """Delete ROS 2 ``node:param`` (it is set) and tell the watchers."""
        params = self._nodes[node]
        size = params.pop(param).size
        self._bytes -= size
        self._node_bytes[node] -= size
        self._count -= 1
        if not params:
            del self._nodes[node]
            del self._node_bytes[node]
        self._shares.release(f"{node}:{param}")
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
            return self._tree.names()
        return sorted(f"{node}:{param}" for node, params in self._nodes.items() for param in params)

    def names_of(self, node: str) -> list[str]:
        """The names of ROS 2 ``node``'s parameters (without the node), in the order set."""
        return list(self._nodes.get(node, ()))

    def holds(self, node: str) -> bool:
        """Whether ROS 2 ``node`` has parameters (``nodes()`` for one node, at no copy)."""
        return node in self._nodes

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

    def held_by(self, client: ClientId) -> tuple[int, int]:
        """``(parameters, bytes)`` charged to ``client`` now (``CLIENT_SHARE``)."""
        return self._shares.held(client)

    def search(self, name: str) -> str:
        """ROS 1 ``search_param`` from the root namespace: the global name if set, else ``""``."""
        key = resolve_name(name)
        return key if self.has(key) else ""

    def watch(self, watcher: ParamWatcher, key: str | None = None) -> Callable[[], None]:
        """Call ``watcher(name, value)`` after every change; returns a function that stops it.

        ``key``: only changes of that name as the store spells it (``key()``), and at
        no cost for a change of another.
        """
        watchers = self._watchers if key is None else self._keyed.setdefault(key, [])
        watchers.append(watcher)

        def stop() -> None:
            if watcher in watchers:
                watchers.remove(watcher)
            if key is not None and not watchers and self._keyed.get(key) is watchers:
                del self._keyed[key]

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

    # ---- clients -------------------------------------------------------------------

    def _check_creator(self, client: ClientId, node: str) -> None:
        """Refuse a parameter ``client`` would create on ``node`` (D34).

        Raises:
            ParameterError: the node does not exist, is the server's, or another
                live client's (a node with a participant other than ``client``,
                none of them in-process code).
        """
        nodes = self._graph_nodes
        if nodes is None:
            return
        if node in SERVER_NODES:
            raise ParameterError(f"node {node} is the server's: no client creates parameters on it")
        members = nodes.clients_of(node)
        if not members and node not in self._nodes:
            raise ParameterError(f"node {node} does not exist")
        if node.startswith(CLIENT_NODE_PREFIX) and members and client not in members:
            raise ParameterError(
                f"node {node} is another client's: a client creates parameters on its own "
                "node or on the robot's"
            )

    def _forgotten(self, client: ClientId, node: str | None) -> None:
        """``client`` left the graph (``Nodes.on_forget``): release what it set (D34).

        The parameters of its own node go with the node; what else it set is left
        behind, and the oldest left behind past one share are deleted.
        """
        if (
            not self.ros1
            and node is not None
            and node.startswith(CLIENT_NODE_PREFIX)
            and node in self._nodes
            and self._graph_nodes is not None
            and not self._graph_nodes.clients_of(node)
        ):
            for param in list(self._nodes[node]):
                self._remove(node, param)
        for key in self._shares.leave(client):
            if self.ros1:
                self._ros1_delete_leaf(key)
            else:
                node_key, _, param = key.partition(":")
                self._remove(node_key, param)

    # ---- internals ---------------------------------------------------------------

    def _notify(self, name: str, value: ParamValue | None) -> None:
        keyed = self._keyed.get(name)
        watchers = self._watchers + keyed if keyed else self._watchers
        for watcher in list(watchers):
            try:
                watcher(name, value)
            except Exception:  # one broken watcher must not stop the others
                _episodes.log(
                    logging.ERROR,
                    "watcher_failed",
                    "parameter watcher failed on %s",
                    name,
                    exc_info=True,
                )

    def _grow(self, new: int, old: int, node: str) -> None:
        """Account for a value of ``old`` bytes of ROS 2 ``node`` becoming one of ``new``.

        Raises:
            ParameterStoreFullError: the values would hold more than ``max_bytes``,
                or ``node``'s more than ``max_node_bytes``; nothing is counted.
        """
        grown = new - old
        total = self._bytes + grown
        if total > self.max_bytes and grown > 0:
            raise ParameterStoreFullError(f"the parameter store is full ({self.max_bytes} bytes)")
        mine = self._node_bytes.get(node, 0) + grown
        if mine > self.max_node_bytes and grown > 0:
            raise ParameterStoreFullError(self._share_full(node, f"{self.max_node_bytes} bytes"))
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
            return self._tree.lookup(resolve_name(name))
        node_key, param = split_ros2_name(name)
        entry = self._nodes.get(node_key, {}).get(param)
        return MISSING if entry is None else entry.value

    # ---- ROS 1 ---------------------------------------------------------------------

    def _ros1_set(self, key: str, value: object, client: ClientId | None) -> None:
        """Set ROS 1 ``key`` (a leaf or a namespace) to ``value``, set by ``client``.

        Raises:
            ParameterStoreFullError: no room for the terminals it adds (the store's,
                the client's share).
            ParameterError: a bad value; the root set to anything but a dict.
        """
        stored = ros1_value(value, key)
        if key == "/" and not isinstance(stored, FrozenNamespace):
            raise ParameterError("the root namespace / can only be set to a dict")
        tree = self._tree
        removed = tree.replaced(key)
        added = tree.added(key, stored)
        count = len(tree.sizes) - len(removed) + len(added)
        if count > self.max_params and count > len(tree.sizes):
            raise ParameterStoreFullError(
                f"the parameter store is full ({self.max_params} parameters)"
            )
        size = tree.bytes - sum(tree.sizes[name] for name in removed) + sum(added.values())
        if size > self.max_bytes and size > tree.bytes:
            raise ParameterStoreFullError(f"the parameter store is full ({self.max_bytes} bytes)")
        if client is not None:
            self._shares.check(client, {**dict.fromkeys(removed), **added})
        tree.set(key, stored, removed, added)
        for name in removed:
            self._shares.release(name)
        for name, name_size in added.items():
            self._shares.charge(name, client, name_size)
        self._notify(key, stored)

    def _ros1_delete_leaf(self, key: str) -> None:
        """Delete the ROS 1 terminal ``key`` (a client's left behind) and tell the watchers."""
        for removed in self._tree.delete(key):
            self._shares.release(removed)
        self._notify(key, None)
