"""RIHS01 type hashes as rosidl computes them, from the graph's own definitions.

ROS 2 (Iron and later) names every type by a hash of its description: rmw_zenoh
puts it in keys and tokens, rclpy reports it for each endpoint. A hash that
differs from the one computed here means the peer's definition is not the
graph's (``rwt_zenoh.payload`` and ``rwt_ros2`` compare them).
"""

from __future__ import annotations

import hashlib
import json
from collections import ChainMap
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Nodetype

from rwt_protocol.errors import RwtError

from .interop import WSTRING_TYPE

if TYPE_CHECKING:
    from .registry import TypeRegistry

__all__ = ["describe_and_hash", "message_type_hash", "rihs01"]


def message_type_hash(registry: TypeRegistry, type_name: str) -> str:
    """The RIHS01 hash (``RIHS01_<hex>``) of a ROS 2 message type of the registry.

    Raises:
        UnknownTypeError, InvalidTypeNameError: the type is not known.
    """
    return rihs01(registry, registry.message(type_name).rosbags_name, {})


def rihs01(registry: TypeRegistry, name: str, made_up: dict[str, Any]) -> str:
    """The RIHS01 of ``name`` over the registry's store plus ``made_up``, as rosidl reads types.

    A ``char`` field counts as ``uint8``, as rosidl reads it from a ``.msg``
    file, and a ``wstring`` as ``wstring``; rosbags alone would hash the first as
    ``char`` and the second as the struct that carries it in CDR.

    Raises:
        KeyError: the store lacks a structure ``name`` refers to.
    """
    definitions = _RosidlDefinitions(made_up, registry.typestore().fielddefs, registry)
    return describe_and_hash(definitions, name)


# rosidl's field type ids (type_description_interfaces/msg/FieldType.msg); an array
# adds 48, a bounded sequence 96, an unbounded one 144
_TYPE_IDS = {
    "int8": 2,
    "uint8": 3,
    "int16": 4,
    "uint16": 5,
    "int32": 6,
    "uint32": 7,
    "int64": 8,
    "uint64": 9,
    "float32": 10,
    "float64": 11,
    "float128": 12,
    "char": 13,
    "wchar": 14,
    "bool": 15,
    "byte": 16,
    "string": 17,
    "wstring": 18,
}
_BOUNDED = {"string": 21, "wstring": 22}
_NESTED = 1
_ARRAY, _BOUNDED_SEQUENCE, _SEQUENCE = 48, 96, 144
_PLACEHOLDER = ("structure_needs_at_least_one_member", (Nodetype.BASE, ("uint8", 0)))


def describe_and_hash(definitions: Mapping[str, Any], name: str) -> str:
    """Rosidl's RIHS01 type hash (REP 2011) of ``name`` over rosbags-style field definitions.

    The SHA-256 of the JSON type description: the type's fields with rosidl's type
    ids, then the types it refers to, sorted by name; ``json.dumps``'s default
    separators, as rosidl_generator_type_description writes it. rosbags'
    ``Typestore.hash_rihs01`` computes the same but knows no ``wstring``, which
    its definitions spell ``string``: ``definitions`` here may say ``wstring``.

    Raises:
        KeyError: a structure ``name`` refers to is not in ``definitions``.
    """
    structs: dict[str, dict[str, Any]] = {}

    def field_of(field_name: str, desc: Any) -> dict[str, Any]:
        offset = capacity = string_capacity = 0
        kind, rest = desc
        if kind == Nodetype.ARRAY:
            offset, capacity = _ARRAY, rest[1]
            kind, rest = rest[0]
        elif kind == Nodetype.SEQUENCE:
            offset, capacity = (_BOUNDED_SEQUENCE, rest[1]) if rest[1] else (_SEQUENCE, 0)
            kind, rest = rest[0]
        nested = ""
        if kind == Nodetype.NAME:
            type_id, nested = offset + _NESTED, rest
            struct(nested)
        elif rest[0] in _BOUNDED and rest[1]:
            type_id, string_capacity = offset + _BOUNDED[rest[0]], rest[1]
        else:
            type_id = offset + _TYPE_IDS[rest[0]]
        return {
            "name": field_name,
            "type": {
                "type_id": type_id,
                "capacity": capacity,
                "string_capacity": string_capacity,
                "nested_type_name": nested,
            },
        }

    def struct(type_name: str) -> dict[str, Any]:
        if type_name not in structs:
            structs[type_name] = {"type_name": type_name, "fields": []}  # before recursing
            fields = definitions[type_name][1] or [_PLACEHOLDER]
            structs[type_name]["fields"] = [field_of(f, desc) for f, desc in fields]
        return structs[type_name]

    description = {
        "type_description": struct(name),
        "referenced_type_descriptions": [
            described for key, described in sorted(structs.items()) if key != name
        ],
    }
    digest = hashlib.sha256(json.dumps(description).encode()).hexdigest()
    return f"RIHS01_{digest}"


class _RosidlDefinitions(Mapping[str, Any]):
    """rosbags' field definitions as rosidl reads them.

    ``made_up`` ones come first, a ``char`` field is ``uint8``, and a ``wstring``
    field is ``wstring`` with its bound from the registry's own definition (the
    store holds it as the struct ``interop.WSTRING_TYPE``).
    """

    def __init__(
        self, made_up: dict[str, Any], store: Mapping[str, Any], registry: TypeRegistry
    ) -> None:
        self._defs = ChainMap(made_up, store)  # type: ignore[arg-type]
        self._registry = registry

    def __getitem__(self, name: str) -> Any:
        consts, fields = self._defs[name]
        wide = self._wide_fields(name)
        return consts, [
            (field, _wide(desc, wide[field]) if field in wide else _uint8_chars(desc))
            for field, desc in fields
        ]

    def _wide_fields(self, name: str) -> dict[str, int]:
        """The ``wstring`` fields of ``name`` and their bounds (0: none)."""
        try:
            mtype = self._registry.message(name)
        except RwtError:  # a made-up structure (a service's event): no wstring there
            return {}
        return {
            spec.name: spec.type.string_bound or 0
            for spec in mtype.fields
            if spec.type.base == "wstring"
        }

    def __iter__(self) -> Iterator[str]:
        return iter(self._defs)

    def __len__(self) -> int:
        return len(self._defs)


def _wide(desc: Any, bound: int) -> Any:
    """A ``wstring`` field's node, whose struct of code units (interop) rosidl calls ``wstring``."""
    kind, rest = desc
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return kind, (_wide(rest[0], bound), rest[1])
    if kind == Nodetype.NAME and rest == WSTRING_TYPE:
        return Nodetype.BASE, ("wstring", bound)
    return desc


def _uint8_chars(desc: Any) -> Any:
    kind, rest = desc
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return kind, (_uint8_chars(rest[0]), rest[1])
    if kind == Nodetype.BASE and rest[0] == "char":
        return kind, ("uint8", rest[1])
    return desc
