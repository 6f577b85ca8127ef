"""Parameters across processes, through ROS 2's parameter services of each node.

Provider side: every node with parameters in this graph answers
``/<node>/list_parameters``, ``/<node>/get_parameters`` and
``/<node>/set_parameters`` (``rcl_interfaces``) on Zenoh, from and into the
graph's parameter store.

Caller side: a remote node's ``list_parameters`` token makes the link keep a
replica of that node's parameters in this graph's store, refreshed through those
services every ``REFRESH_SWEEPS`` sweeps, so rosapi here lists and reads them; a
change made here to a replica (rosapi ``set_param``) is sent to the node's
``set_parameters``; the replica goes with the node's token. ROS 2 parameters
keep their type; rwt's store does too.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

from rwt_graph.calls import guarded
from rwt_graph.params import ParameterError
from rwt_protocol.errors import RwtError

from .payload import decode_message, encode_message, service_hash
from .wire import Topic, WireError, dds_type_name, topic_keyexpr

if TYPE_CHECKING:
    from collections.abc import Callable

    import zenoh
    from rwt_graph.params import ParamValue

    from .link import ZenohLink, _Remote

__all__ = ["ParamLink"]

logger = logging.getLogger("rwt.zenoh")

SERVICES = {
    "list_parameters": "rcl_interfaces/srv/ListParameters",
    "get_parameters": "rcl_interfaces/srv/GetParameters",
    "set_parameters": "rcl_interfaces/srv/SetParameters",
}
REFRESH_SWEEPS = 5
"""Replicas are refreshed every this many sweeps (0.5 s with the default sweep)."""

# rcl_interfaces/msg/ParameterType
_NOT_SET, _BOOL, _INTEGER, _DOUBLE, _STRING = 0, 1, 2, 3, 4
_BYTES, _BOOLS, _INTEGERS, _DOUBLES, _STRINGS = 5, 6, 7, 8, 9
_FIELDS = {
    _BOOL: "bool_value",
    _INTEGER: "integer_value",
    _DOUBLE: "double_value",
    _STRING: "string_value",
    _BYTES: "byte_array_value",
    _BOOLS: "bool_array_value",
    _INTEGERS: "integer_array_value",
    _DOUBLES: "double_array_value",
    _STRINGS: "string_array_value",
}


def _type_of(value: object) -> int:
    if isinstance(value, bool):
        return _BOOL
    if isinstance(value, int):
        return _INTEGER
    if isinstance(value, float):
        return _DOUBLE
    if isinstance(value, str):
        return _STRING
    if isinstance(value, bytes | bytearray):
        return _BYTES
    if isinstance(value, list):
        kinds = {_type_of(item) for item in value} or {_STRING}
        if kinds == {_BOOL}:
            return _BOOLS
        if kinds == {_INTEGER}:
            return _INTEGERS
        if kinds <= {_INTEGER, _DOUBLE}:
            return _DOUBLES
        if kinds == {_STRING}:
            return _STRINGS
    raise ParameterError(f"a value of type {type(value).__name__} is no ROS 2 parameter")


@dataclass(eq=False)
class _Replica:
    """A remote node whose parameters this graph holds a copy of."""

    remote: _Remote
    names: set[str] = field(default_factory=set)


class ParamLink:
    """The parameter half of a ``ZenohLink`` (see the module text)."""

    def __init__(self, link: ZenohLink) -> None:
        self.link = link
        registry = link.graph.registry
        self._types = {part: registry.service(name) for part, name in SERVICES.items()}
        self._value_type = registry.message("rcl_interfaces/msg/ParameterValue")
        self._offers: dict[str, list[Any]] = {}
        self._replicas: dict[str, _Replica] = {}
        self._applying = False
        self._ticks = 0
        self._stop_watching: Callable[[], None] | None = link.graph.params.watch(self._changed)

    # ---- values ------------------------------------------------------------------

    def to_wire(self, value: ParamValue) -> dict[str, object]:
        """A parameter value as ``rcl_interfaces/msg/ParameterValue`` (internal form)."""
        msg = self._value_type.default()
        kind = _type_of(value)
        msg["type"] = kind
        msg[_FIELDS[kind]] = bytes(value) if kind == _BYTES else value  # type: ignore[arg-type]
        return msg

    @staticmethod
    def from_wire(msg: dict[str, object]) -> object:
        """The value of a ``ParameterValue``; None when NOT_SET.

        Raises:
            ParameterError: an unknown type code.
        """
        kind = msg.get("type")
        if kind == _NOT_SET:
            return None
        name = _FIELDS.get(kind) if isinstance(kind, int) else None
        if name is None:
            raise ParameterError(f"unknown parameter type {kind!r}")
        value = msg[name]
        return list(value) if isinstance(value, tuple) else value

    # ---- provider side --------------------------------------------------------------

    def sweep(self) -> None:
        """Offer each local node's parameter services; refresh the replicas now and then."""
        link = self.link
        local = {node for node in link.graph.params.nodes() if node not in self._replicas}
        for node in list(self._offers):
            if node not in local:
                for handle in self._offers.pop(node):
                    guarded("undeclaring a parameter service", handle.undeclare)
        for node in local - self._offers.keys():
            try:
                self._offer(node)
            except (RwtError, WireError) as exc:
                logger.debug("zenoh link: parameters of %s are not shared: %s", node, exc)
        self._ticks += 1
        if self._ticks % REFRESH_SWEEPS == 0:
            for node in list(self._replicas):
                self._refresh(node)

    def _offer(self, node: str) -> None:
        link = self.link
        handles: list[Any] = []
        for part, srvtype in self._types.items():
            hash_text = service_hash(link.graph.registry, srvtype)
            topic = Topic(f"{node}/{part}", dds_type_name(srvtype.name), hash_text)
            handles += link.declare_service(node, topic, self._on_query_thread(node, part))
        self._offers[node] = handles

    def _on_query_thread(self, node: str, part: str) -> Callable[[zenoh.Query], None]:
        def on_query(query: zenoh.Query) -> None:  # a Zenoh thread
            self.link.soon(self._answer, node, part, query)

        return on_query

    def _answer(self, node: str, part: str, query: zenoh.Query) -> None:
        registry = self.link.graph.registry
        srvtype = self._types[part]
        try:
            payload = query.payload
            request = decode_message(
                registry, srvtype.request, b"" if payload is None else payload.to_bytes()
            )
            response = getattr(self, f"_{part}")(node, request)
            self.link.reply(query, encode_message(registry, srvtype.response, response))
        except (RwtError, WireError) as exc:
            query.reply_err(f"{node}/{part} failed: {exc}")
        finally:
            query.drop()  # type: ignore[no-untyped-call]

    def _params_of(self, node: str) -> list[str]:
        prefix = f"{node}:"
        params = self.link.graph.params
        return [name[len(prefix) :] for name in params.names() if name.startswith(prefix)]

    def _list_parameters(self, node: str, request: dict[str, object]) -> dict[str, object]:
        return {"result": {"names": self._params_of(node), "prefixes": []}}

    def _get_parameters(self, node: str, request: dict[str, object]) -> dict[str, object]:
        params = self.link.graph.params
        values = []
        names = request.get("names")
        for name in names if isinstance(names, list) else []:
            value = params.get(f"{node}:{name}", None)
            values.append(self._value_type.default() if value is None else self.to_wire(value))
        return {"values": values}

    def _set_parameters(self, node: str, request: dict[str, object]) -> dict[str, object]:
        params = self.link.graph.params
        results = []
        parameters = request.get("parameters")
        for parameter in parameters if isinstance(parameters, list) else []:
            assert isinstance(parameter, dict)
            name = f"{node}:{parameter['name']}"
            try:
                value = self.from_wire(parameter["value"])
                if value is None:
                    params.delete(name)
                else:
                    params.set(name, value)
                results.append({"successful": True, "reason": ""})
            except ParameterError as exc:
                results.append({"successful": False, "reason": exc.message})
        return {"results": results}

    # ---- caller side --------------------------------------------------------------

    def mirror(self, remote: _Remote) -> None:
        """Start a replica if ``remote`` is a node's ``list_parameters`` service."""
        topic = remote.entity.topic
        assert topic is not None
        suffix = "/list_parameters"
        if not topic.name.endswith(suffix) or topic.dds_type != dds_type_name(
            SERVICES["list_parameters"]
        ):
            return
        node = topic.name[: -len(suffix)]
        if node in self._offers or node in self._replicas:
            return  # this process's own node, or already held
        self._replicas[node] = _Replica(remote)
        self._refresh(node)

    def unmirror(self, remote: _Remote) -> None:
        """Drop the replica of ``remote``'s node (its token went)."""
        for node, replica in list(self._replicas.items()):
            if replica.remote is remote:
                del self._replicas[node]
                self._apply(node, {}, replica)

    def _key(self, node: str, part: str) -> str:
        dds = dds_type_name(SERVICES[part])
        return topic_keyexpr(self.link.domain_id, f"{node}/{part}", dds, "*")

    def _refresh(self, node: str) -> None:
        registry = self.link.graph.registry
        link = self.link

        def listed(ok: bool, value: object) -> None:
            if not ok or node not in self._replicas:
                return
            assert isinstance(value, bytes)
            names = decode_message(registry, self._types["list_parameters"].response, value)
            result = names["result"]
            assert isinstance(result, dict)
            wanted = list(result["names"])
            request = encode_message(
                registry, self._types["get_parameters"].request, {"names": wanted}
            )
            link.query(
                self._key(node, "get_parameters"),
                request,
                lambda ok, value: got(ok, value, wanted),
                link.call_timeout_s,
            )

        def got(ok: bool, value: object, names: list[str]) -> None:
            replica = self._replicas.get(node)
            if not ok or replica is None:
                return
            assert isinstance(value, bytes)
            reply = decode_message(registry, self._types["get_parameters"].response, value)
            values = reply["values"]
            assert isinstance(values, list)
            found = {name: self.from_wire(item) for name, item in zip(names, values, strict=False)}
            self._apply(node, {k: v for k, v in found.items() if v is not None}, replica)

        request = encode_message(
            registry, self._types["list_parameters"].request, {"prefixes": [], "depth": 0}
        )
        link.query(self._key(node, "list_parameters"), request, listed, link.call_timeout_s)

    def _apply(self, node: str, values: dict[str, object], replica: _Replica) -> None:
        """Make the store's copy of ``node`` hold exactly ``values`` (no echo to the node)."""
        params = self.link.graph.params
        self._applying = True
        try:
            for name in replica.names - values.keys():
                guarded(f"forgetting {node}:{name}", partial(params.delete, f"{node}:{name}"))
            for name, value in values.items():
                full = f"{node}:{name}"
                if params.get(full, None) != value:
                    try:
                        params.set(full, value)
                    except ParameterError:  # another type now: replace it
                        guarded(f"replacing {full}", partial(_replace, params, full, value))
            replica.names = set(values)
        finally:
            self._applying = False

    def _changed(self, name: str, value: ParamValue | None) -> None:
        """A change in this store: one made here to a replica goes to its node."""
        if self._applying:
            return
        node, _, param = name.partition(":")
        if node not in self._replicas:
            return
        registry = self.link.graph.registry
        wire = self._value_type.default() if value is None else self.to_wire(value)
        request = encode_message(
            registry,
            self._types["set_parameters"].request,
            {"parameters": [{"name": param, "value": wire}]},
        )
        self.link.query(
            self._key(node, "set_parameters"),
            request,
            lambda ok, value: self._refresh(node),
            self.link.call_timeout_s,
        )

    def close(self) -> None:
        """Withdraw the services and forget the replicas."""
        if self._stop_watching is not None:
            self._stop_watching()
            self._stop_watching = None
        for handles in self._offers.values():
            for handle in handles:
                guarded("undeclaring a parameter service", handle.undeclare)
        self._offers.clear()
        for node, replica in list(self._replicas.items()):
            self._apply(node, {}, replica)
        self._replicas.clear()


def _replace(params: Any, name: str, value: object) -> None:
    params.delete(name)
    params.set(name, value)
