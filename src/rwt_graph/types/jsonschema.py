"""JSON Schema (draft 2020-12) of a ROS message type, from rosapi's ``message_details``.

One rule for every front end that describes messages to a client that reads JSON
Schema: the MCP tools' input schemas and the HTTP API's OpenAPI document.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["json_schema"]

# fieldtypes as rosapi spells them: the .msg names (ROS 1) and the IDL names (ROS 2)
_PRIMITIVES: dict[str, dict[str, object]] = {
    **{name: {"type": "boolean"} for name in ("bool", "boolean")},
    **{name: {"type": "number"} for name in ("float32", "float64", "float", "double")},
    **{name: {"type": "string"} for name in ("string", "wstring")},
    **{
        name: {"type": "integer"}
        for name in (
            "byte",
            "octet",
            "char",
            "int8",
            "uint8",
            "int16",
            "uint16",
            "int32",
            "uint32",
            "int64",
            "uint64",
        )
    },
}
_BYTES = {
    "anyOf": [
        {"type": "string", "contentEncoding": "base64"},
        {"type": "array", "items": {"type": "integer", "minimum": 0, "maximum": 255}},
    ]
}


def json_schema(typedefs: list[dict[str, object]]) -> dict[str, object]:
    """A JSON schema (draft 2020-12) for messages of the first of ``typedefs``.

    Args:
        typedefs: rosapi's ``message_details`` answer, the root type first: each
            ``{"type", "fieldnames", "fieldtypes", "fieldarraylen"}`` (array length
            -1: not an array, 0: any length, N: exactly N).

    Returns:
        The root type's schema, its nested types under ``$defs`` by type name
        and referred to by ``$ref`` (``#/$defs/geometry_msgs~1Vector3``: a JSON
        pointer, ``/`` escaped); a ``uint8[]`` or ``char[]`` field takes base64 text or a
        list of 0-255, as rosbridge's JSON does. An empty schema for no typedefs.
        A field name's leading ``_`` is dropped: ROS field names start with a
        letter, and rosbridge_suite 2.1.0's rosapi on ROS 2 Kilted reports the
        Python slots (``_linear``) instead (docs/agents.md).
    """
    if not typedefs:
        return {}
    known = {str(typedef.get("type")) for typedef in typedefs}
    defs = {str(typedef.get("type")): _object_schema(typedef, known) for typedef in typedefs}
    root = str(typedefs[0].get("type"))
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **defs[root], "$defs": defs}


def _object_schema(typedef: Mapping[str, object], known: set[str]) -> dict[str, object]:
    names, types, lengths = (
        _list(typedef.get(key)) for key in ("fieldnames", "fieldtypes", "fieldarraylen")
    )
    properties: dict[str, object] = {}
    for index, (name, field_type) in enumerate(zip(names, types, strict=False)):
        length = lengths[index] if index < len(lengths) else -1
        properties[str(name).removeprefix("_")] = _field_schema(str(field_type), int(length), known)
    return {"type": "object", "title": str(typedef.get("type")), "properties": properties}


def _field_schema(field_type: str, length: int, known: set[str]) -> object:
    if length >= 0 and field_type in ("uint8", "char", "byte", "octet"):
        return _BYTES
    base, _, bound = field_type.partition("<")  # a bounded string: string<10>
    item: object = _PRIMITIVES.get(base)
    if item is not None and bound.rstrip(">").isdigit():
        item = {**_PRIMITIVES[base], "maxLength": int(bound.rstrip(">"))}
    if item is None:
        pointer = field_type.replace("~", "~0").replace("/", "~1")  # RFC 6901 escapes
        item = {"$ref": f"#/$defs/{pointer}"} if field_type in known else {}
    if length < 0:
        return item
    schema: dict[str, object] = {"type": "array", "items": item}
    if length > 0:
        schema |= {"minItems": length, "maxItems": length}
    return schema


def _list(value: object) -> list[Any]:
    return value if isinstance(value, list) else []
