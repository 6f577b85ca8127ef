"""Parameter values: checked once when set, then held frozen and shared by every reader.

A value the store holds is never changed again, so ``Parameters.get`` and every
watcher get the held object itself, not a copy (docs/embedding.md, "Nodes and
parameters"): a list is held as a ``tuple``, a ROS 1 namespace as a
``FrozenNamespace`` (a ``dict`` that refuses changes), a byte array as ``bytes``.
Checking a value costs C-level passes over it where it is an array of one Python
type (``set(map(type, value))``, ``min``, ``max``, one ``str.join``), so a large
array costs about what copying it once does; anything else is checked item by item.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from enum import StrEnum
from typing import TYPE_CHECKING, Any, NoReturn, TypeAlias

from rwt_protocol.codecs.json import valid_unicode
from rwt_protocol.errors import GraphError

if TYPE_CHECKING:
    from collections.abc import Sequence

__all__ = [
    "FrozenNamespace",
    "ParamKind",
    "ParamValue",
    "ParameterError",
    "ParameterNotSetError",
    "ParameterStoreFullError",
    "as_held",
    "json_text",
    "ros1_value",
    "ros2_value",
    "to_json_safe",
    "value_size",
]

ParamValue: TypeAlias = (
    "bool | int | float | str | bytes | tuple[ParamValue, ...] | Mapping[str, ParamValue]"
)
"""A held value: a scalar, ``bytes``, a tuple, or (ROS 1) a namespace (``FrozenNamespace``)."""

_INT64 = (-(2**63), 2**63 - 1)
_INT32 = (-(2**31), 2**31 - 1)  # XML-RPC integers of the ROS 1 parameter server
_NUMBERS = frozenset({bool, int, float})


class ParameterError(GraphError):
    """A parameter operation was refused: bad name, bad value, type change, read-only."""


class ParameterNotSetError(ParameterError):
    """The parameter does not exist."""


class ParameterStoreFullError(ParameterError):
    """No room for it: the store is full, or a node or client holds its share."""


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
_EXACT = {
    bool: ParamKind.BOOL,
    int: ParamKind.INTEGER,
    float: ParamKind.DOUBLE,
    str: ParamKind.STRING,
}


class FrozenNamespace(dict[str, Any]):
    """A ROS 1 namespace the store holds: a ``dict`` whose methods refuse changes.

    A ``dict`` subclass, not ``types.MappingProxyType``: JSON, msgspec and CBOR
    encoders take it as the dict it is. Copying gives the same object (it cannot
    change). Raises ``TypeError`` on any change.
    """

    __slots__ = ()

    def _refuse(self, *args: object, **kwargs: object) -> NoReturn:
        raise TypeError("a parameter value the store holds cannot be changed")

    __setitem__ = __delitem__ = __ior__ = _refuse
    clear = pop = popitem = setdefault = update = _refuse

    def __copy__(self) -> FrozenNamespace:
        return self

    def __deepcopy__(self, memo: object) -> FrozenNamespace:
        return self

    def __reduce__(self) -> tuple[type[FrozenNamespace], tuple[dict[str, Any]]]:
        return FrozenNamespace, (dict(self),)


EMPTY_NAMESPACE = FrozenNamespace()


def _check_text(value: str, what: str) -> None:
    """Refuse a string no wire form holds (JSON, UTF-8, CDR), so every reader can read it."""
    if not valid_unicode(value):
        raise ParameterError(f"{what}: a string is not valid Unicode (lone surrogate)")


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


_CONVERT: dict[ParamKind, Any] = {
    ParamKind.BOOL: bool,
    ParamKind.INTEGER: int,
    ParamKind.DOUBLE: float,
    ParamKind.STRING: str,
}


def _plain(item: object, kind: ParamKind) -> Any:
    """``item`` as the exact type of ``kind`` (an ``IntEnum`` member as its ``int``...)."""
    return _CONVERT[kind](item)


def _within(value: Sequence[Any], bounds: tuple[int, int]) -> bool:
    """Whether the numbers of ``value`` lie within ``bounds`` (two C-level passes)."""
    return bool(bounds[0] <= min(value) and max(value) <= bounds[1])


def _fast_array(value: Sequence[Any], types: set[type]) -> tuple[tuple[Any, ...], ParamKind] | None:
    """``value`` checked by whole-array passes if its items are of one exact type, else None."""
    kind = _EXACT.get(next(iter(types))) if len(types) == 1 else None
    if kind is ParamKind.INTEGER and not _within(value, _INT64):
        return None  # the item by item check names the one out of range
    if kind is ParamKind.STRING and not valid_unicode("".join(value)):
        return None
    if kind is not None:
        return (value if type(value) is tuple else tuple(value)), _ARRAY_OF[kind]
    if types == {int, float} and _within(value, _INT64):  # a float out of range goes slow
        return tuple(map(float, value)), ParamKind.DOUBLE_ARRAY
    return None


def ros2_value(value: object, what: str = "value") -> tuple[ParamValue, ParamKind]:
    """Check a ROS 2 parameter value; return it frozen (a list as a tuple) and its kind.

    ``bytes`` (or ``bytearray``) is a byte array (``ParameterType`` 5), held as
    ``bytes``; ints in a list with floats become floats (a double array).

    Raises:
        ParameterError: not a ROS 2 parameter value (dicts, None, nested or mixed lists,
            a list of bytes, an integer outside int64, a lone surrogate).
    """
    if isinstance(value, bytes | bytearray):
        return bytes(value), ParamKind.BYTE_ARRAY
    if not isinstance(value, list | tuple):
        kind = _scalar_kind(value, what)
        scalar: ParamValue = _plain(value, kind) if type(value) not in _EXACT else value  # type: ignore[assignment]
        return scalar, kind
    if not value:
        return (), ParamKind.EMPTY_ARRAY
    fast = _fast_array(value, set(map(type, value)))
    if fast is not None:
        return fast
    kinds = {_scalar_kind(item, f"{what}[]") for item in value}
    if kinds == {ParamKind.INTEGER, ParamKind.DOUBLE}:
        return tuple(map(float, value)), ParamKind.DOUBLE_ARRAY
    if len(kinds) != 1:
        raise ParameterError(f"{what}: the items of a ROS 2 array parameter must have one type")
    kind = kinds.pop()
    return tuple(_plain(item, kind) for item in value), _ARRAY_OF[kind]


def _ros1_fast(value: Sequence[Any]) -> tuple[Any, ...] | None:
    """A ROS 1 list of plain scalars checked by whole-list passes, else None."""
    types = set(map(type, value))
    if types <= _NUMBERS and _within(value, _INT32):
        return tuple(value)  # floats within int32 too: none can be an int out of range
    if types == {float}:
        return tuple(value)
    if types == {str} and valid_unicode("".join(value)):
        return tuple(value)
    return None


def ros1_value(value: object, what: str = "value") -> ParamValue:
    """Check a ROS 1 parameter value (XML-RPC: no None, int32 integers); return it frozen.

    Lists become tuples, dicts ``FrozenNamespace`` (namespaces).

    Raises:
        ParameterError: None, a non-str or empty dict key or one holding ``/``, an
            integer outside int32, a lone surrogate, another type.
    """
    if isinstance(value, str):
        _check_text(value, what)
        return str(value)
    if isinstance(value, bool):
        return bool(value)
    if isinstance(value, float):
        return float(value)
    if isinstance(value, int):
        if not _INT32[0] <= value <= _INT32[1]:
            raise ParameterError(f"{what}: integer {value} does not fit in int32")
        return int(value)
    if isinstance(value, list | tuple):
        fast = _ros1_fast(value) if value else ()
        if fast is not None:
            return fast
        return tuple(ros1_value(item, f"{what}[{i}]") for i, item in enumerate(value))
    if isinstance(value, Mapping):
        out: dict[str, ParamValue] = {}
        for key, item in value.items():
            if not isinstance(key, str) or not key or "/" in key:
                raise ParameterError(f"{what}: namespace keys are non-empty names, got {key!r}")
            _check_text(key, what)
            out[key] = ros1_value(item, f"{what}.{key}")
        return FrozenNamespace(out)
    raise ParameterError(f"{what}: a ROS 1 parameter cannot be {type(value).__name__}")


def as_held(held: object, value: ParamValue) -> ParamValue:
    """``value`` as bytes when ``held`` is a byte array and ``value`` a list of octets.

    JSON has no bytes: rosapi's ``get_param`` answers a byte array as its octets
    (``to_json_safe``), so a client writing back what it read sends a list of ints
    0-255; for a byte-array parameter that is the same byte array (D9 reads a
    ``byte[]`` field from JSON the same way). Any other value is returned as it is.
    """
    if not isinstance(held, bytes) or not isinstance(value, list | tuple):
        return value
    if set(map(type, value)) <= {int} and (not value or _within(value, (0, 255))):
        return bytes(value)  # type: ignore[arg-type]  # ints 0-255, checked
    return value


def value_size(value: object) -> int:
    """Count the bytes a parameter value holds against the store's byte bounds.

    UTF-8 bytes of strings and keys, the length of a byte array, 8 per number or
    bool, summed over lists and dicts; a list of numbers or of strings is counted
    in C-level passes.
    """
    if isinstance(value, str):
        return len(value) if value.isascii() else len(value.encode("utf-8", "surrogatepass"))
    if isinstance(value, bytes):
        return len(value)
    if isinstance(value, Mapping):
        return sum(value_size(key) + value_size(item) for key, item in value.items())
    if isinstance(value, list | tuple):
        types = set(map(type, value))
        if types <= _NUMBERS:
            return 8 * len(value)
        if types == {str}:
            return value_size("".join(value))
        return sum(value_size(item) for item in value)
    return 8


def to_json_safe(value: object) -> object:
    """``value`` with non-finite floats as None and bytes as a list of octets, for JSON text (D10).

    A byte array becomes its octets (ints 0-255), as a ``byte[]`` field of a
    message goes out in JSON (docs/ros2.md, "Parameters"). Builds a new structure:
    ``json_text`` calls it only for values that hold a non-finite float.
    """
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, bytes):
        return list(value)
    if isinstance(value, list | tuple):
        return [to_json_safe(item) for item in value]
    if isinstance(value, Mapping):
        return {key: to_json_safe(item) for key, item in value.items()}
    return value


def _octets(value: object) -> object:
    if isinstance(value, bytes):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


def json_text(value: object) -> str:
    """``value`` as JSON text (rosapi's ``get_param``): non-finite floats as null (D10).

    One pass of the C encoder (tuples as arrays, bytes as their octets); only a
    value holding NaN or an infinity is walked in Python (``to_json_safe``).
    """
    try:
        return json.dumps(value, ensure_ascii=False, allow_nan=False, default=_octets)
    except ValueError:  # "Out of range float values are not JSON compliant"
        return json.dumps(to_json_safe(value), ensure_ascii=False)
