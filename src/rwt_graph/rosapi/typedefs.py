r"""``rosapi/TypeDef`` descriptions of message types (REF §7.1 message_details and friends).

A TypeDef is ``{type, fieldnames, fieldtypes, fieldarraylen, examples, constnames,
constvalues}``, all parallel lists of strings except ``fieldarraylen``:

- ``type`` is ``pkg/Type`` in both dialects (``std_srvs/SetBool_Request`` for a
  ROS 2 request part, ``std_srvs/SetBoolRequest`` in ROS 1);
- ``fieldtypes`` are, in ROS 2, the IDL names rclpy reports (``boolean``,
  ``octet``, ``float``, ``double``, ``uint8`` for ``char``, ``string<N>`` for a
  bounded string), in ROS 1 the ``.msg`` names (``time`` included); nested types
  are ``pkg/Type``, matching the ``type`` of their own TypeDef (roslibjs
  ``decodeTypeDefs`` relies on that);
- ``fieldarraylen`` is -1 for a single value, 0 for an unbounded or bounded
  array, N for a fixed array of N;
- ``examples`` are ``"[]"`` for arrays, ``"{}"`` for nested messages, otherwise
  the default as Python prints it (``"0"``, ``"0.0"``, ``"False"``, ``""``; a
  default written in the definition, such as a quaternion's ``w``, shows as
  ``"1.0"``). ``byte`` (``octet``) shows ``"0"`` where rclpy would print ``b'\\x00'``.

The list starts with the asked type, followed by every nested type once, depth
first. ROS 1 ``time``/``duration`` get a made-up TypeDef (``secs``/``nsecs``), as
rosapi does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..types import ArrayKind, Dialect, FieldSpec, FieldType, MessageType

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["TypeDef", "typedef_name", "typedefs"]

TypeDef = dict[str, object]

_ROS2_NAMES = {
    "bool": "boolean",
    "byte": "octet",
    "char": "uint8",
    "float32": "float",
    "float64": "double",
}
_ROS1_SPECIALS = ("time", "duration")


def typedef_name(canonical: str) -> str:
    """``pkg/msg/Type`` (or ``pkg/Type``) as rosapi spells it: ``pkg/Type``."""
    package, _, rest = canonical.partition("/")
    return f"{package}/{rest.rpartition('/')[2]}"


def _is_special(ftype: FieldType, dialect: Dialect) -> bool:
    return dialect is Dialect.ROS1 and not ftype.is_message and ftype.base in _ROS1_SPECIALS


def _field_type(ftype: FieldType, dialect: Dialect) -> str:
    if ftype.is_message:
        return typedef_name(ftype.base)
    if dialect is Dialect.ROS1:
        return ftype.base
    name = _ROS2_NAMES.get(ftype.base, ftype.base)
    return name if ftype.string_bound is None else f"{name}<{ftype.string_bound}>"


def _array_len(ftype: FieldType) -> int:
    if ftype.array is ArrayKind.NONE:
        return -1
    if ftype.array is ArrayKind.FIXED:
        return ftype.length or 0
    return 0


def _zero(base: str) -> object:
    if base == "bool":
        return False
    if base in ("float32", "float64"):
        return 0.0
    if base in ("string", "wstring"):
        return ""
    return 0


def _example(spec: FieldSpec, dialect: Dialect) -> str:
    ftype = spec.type
    if ftype.array is not ArrayKind.NONE:
        return "[]"
    if ftype.is_message or _is_special(ftype, dialect):
        return "{}"
    value = spec.default if spec.default is not None else _zero(ftype.base)
    if ftype.base in ("float32", "float64") and isinstance(value, int):
        value = float(value)
    return str(value)  # as Python prints it: rosapi builds examples with str()


def _special(name: str) -> TypeDef:
    return {
        "type": name,
        "fieldnames": ["secs", "nsecs"],
        "fieldtypes": ["int32", "int32"],
        "fieldarraylen": [-1, -1],
        "examples": ["0", "0"],
        "constnames": [],
        "constvalues": [],
    }


def typedef(msgtype: MessageType) -> TypeDef:
    """The TypeDef of one message type (nested types not included)."""
    dialect = msgtype.dialect
    return {
        "type": typedef_name(msgtype.name),
        "fieldnames": [spec.name for spec in msgtype.fields],
        "fieldtypes": [_field_type(spec.type, dialect) for spec in msgtype.fields],
        "fieldarraylen": [_array_len(spec.type) for spec in msgtype.fields],
        "examples": [_example(spec, dialect) for spec in msgtype.fields],
        "constnames": [const.name for const in msgtype.constants],
        "constvalues": [str(const.value) for const in msgtype.constants],
    }


def typedefs(msgtype: MessageType, resolve: Callable[[str], MessageType]) -> list[TypeDef]:
    """TypeDefs of ``msgtype`` and of every type nested in it, each once, depth first.

    Args:
        msgtype: the root type.
        resolve: finds a nested type by canonical name (``TypeRegistry.message``).
    """
    found: list[TypeDef] = []
    seen = {msgtype.name}

    def visit(current: MessageType) -> None:
        found.append(typedef(current))
        for spec in current.fields:
            base = spec.type.base
            if base in seen:
                continue
            if spec.type.is_message:
                seen.add(base)
                visit(resolve(base))
            elif _is_special(spec.type, current.dialect):
                seen.add(base)
                found.append(_special(base))

    visit(msgtype)
    return found
