"""Checkers for primitive values and primitive arrays (D9, D10).

Each checker takes one JSON-decoded value and returns it in the internal form, or
raises :class:`Problem`. A ``Problem`` carries the text and the part of the JSON
path below the field (``[3]`` for an array element); the message converter adds
the field's own path and turns it into a ``FieldError``. Checkers are built once
per field type and closed over their limits, so a call does no introspection.
"""

from __future__ import annotations

import binascii
import math
from collections.abc import Callable
from typing import cast

import pybase64

from . import arrays
from .names import Dialect
from .problem import FLOAT32_MAX, Problem
from .spec import ArrayKind, FieldType, int_range, is_bytes_base

__all__ = [
    "FLOAT32_MAX",
    "NUMPY_DTYPES",
    "Checker",
    "Problem",
    "array_checker",
    "json_kind",
    "scalar_checker",
    "zero_value",
]

NUMPY_DTYPES: dict[str, str] = {
    name: name
    for name in (
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "float32",
        "float64",
    )
}
"""The numpy dtype of each numeric primitive (it has the primitive's name); ``bool``,
``char`` and ``byte`` are left to their users (a byte is uint8 in ROS 2, int8 in ROS 1)."""

Checker = Callable[[object], object]

_JSON_KINDS: dict[type, str] = {
    str: "str",
    int: "int",
    float: "float",
    bool: "bool",
    type(None): "null",
    list: "array",
    tuple: "array",
    dict: "object",
}


def json_kind(value: object) -> str:
    """The JSON name of a value's kind: str, int, float, bool, null, array or object."""
    kind = _JSON_KINDS.get(type(value))
    if kind is not None:
        return kind
    if isinstance(value, dict):
        return "object"
    if isinstance(value, list | tuple):
        return "array"
    return type(value).__name__


def _int_checker(name: str, low: int, high: int) -> Checker:
    def check(value: object) -> object:
        if type(value) is int and low <= value <= high:
            return value
        if type(value) is int:
            raise Problem(f"expected {name} in [{low}, {high}], got {value}")
        raise Problem(f"expected {name}, got {json_kind(value)}")

    return check


def _float_checker(name: str, limit: float) -> Checker:
    def check(value: object) -> object:
        kind = type(value)
        if kind is float:
            result: float = value  # type: ignore[assignment]
        elif kind is int:
            try:
                result = float(value)  # type: ignore[arg-type]
            except OverflowError:
                raise Problem(f"expected {name} in [{-limit!r}, {limit!r}], got {value}") from None
        elif value is None:
            return math.nan  # D10: null means NaN
        else:
            raise Problem(f"expected {name}, got {json_kind(value)}")
        if limit < abs(result) < math.inf:
            raise Problem(f"expected {name} in [{-limit!r}, {limit!r}], got {value!r}")
        return result

    return check


def _bool_check(value: object) -> object:
    if value is True or value is False:
        return value
    raise Problem(f"expected bool, got {json_kind(value)}")


def _string_checker(name: str, bound: int | None) -> Checker:
    if bound is None:

        def check(value: object) -> object:
            if type(value) is str:
                return value
            raise Problem(f"expected {name}, got {json_kind(value)}")

        return check

    def check_bounded(value: object) -> object:
        if type(value) is not str:
            raise Problem(f"expected {name}<={bound}, got {json_kind(value)}")
        if len(value) > bound:
            raise Problem(f"expected {name} of at most {bound} characters, got {len(value)}")
        return value

    return check_bounded


def scalar_checker(base: str, dialect: Dialect, string_bound: int | None = None) -> Checker:
    """Build the checker of one primitive value.

    Args:
        base: a primitive name other than ``time``/``duration``.
        dialect: decides what ``byte`` means (REF §4.1).
        string_bound: N of ``string<=N``.

    Returns:
        A function mapping a JSON value to the internal form (ints, floats -
        with ``null`` as NaN -, bools, strs) and raising :class:`Problem` when
        the value does not fit (D9).

    Raises:
        ValueError: ``base`` is not such a primitive.
    """
    ints = int_range(base, dialect)
    if ints is not None:
        return _int_checker(base, *ints)
    if base == "float64":
        return _float_checker(base, 1.7976931348623157e308)
    if base == "float32":
        return _float_checker(base, FLOAT32_MAX)
    if base == "bool":
        return _bool_check
    if base in ("string", "wstring"):
        return _string_checker(base, string_bound)
    raise ValueError(f"not a scalar primitive: {base!r}")


def _length_check(ftype: FieldType, count: int) -> None:
    if ftype.array is ArrayKind.FIXED and count != ftype.length:
        raise Problem(f"expected {ftype.length} elements, got {count}")
    if ftype.array is ArrayKind.BOUNDED and count > (ftype.length or 0):
        raise Problem(f"expected at most {ftype.length} elements, got {count}")


def _each(element: Checker, values: list[object] | tuple[object, ...]) -> list[object]:
    out: list[object] = []
    for index, item in enumerate(values):
        try:
            out.append(element(item))
        except Problem as problem:
            raise Problem(problem.problem, f"[{index}]{problem.suffix}") from None
    return out


def _bytes_checker(ftype: FieldType, element: Checker) -> Checker:
    spelled = ftype.spelled()

    def check(value: object) -> object:
        if type(value) is str:
            try:  # pybase64: SIMD, 20x the stdlib on a camera frame; same strict rules
                data = pybase64.b64decode(value, validate=True)
            except (binascii.Error, ValueError):
                raise Problem(f"expected {spelled} as base64, got invalid base64") from None
        elif type(value) is list or type(value) is tuple:
            if value and set(map(type, value)) != {int}:
                _each(element, value)
            try:
                data = bytes(value)
            except ValueError:
                _each(element, value)
                raise  # pragma: no cover - _each raised for the offending element
        elif isinstance(value, bytes | bytearray | memoryview):
            data = bytes(value)
        elif arrays.is_ndarray(value):  # a CBOR typed array (D27)
            octets = arrays.octet_bytes(value)  # type: ignore[arg-type]
            return check(value.tolist() if octets is None else octets)  # type: ignore[attr-defined]
        else:
            raise Problem(f"expected {spelled} (base64 string or array), got {json_kind(value)}")
        _length_check(ftype, len(data))
        return data

    return check


def _list_checker(
    ftype: FieldType,
    element: Checker,
    fast: Callable[[list[object]], bool],
    numeric: Callable[[object], object | None] | None = None,
) -> Checker:
    """An array checker; ``numeric`` takes numpy arrays whole (None: check them as lists)."""
    spelled = ftype.spelled()

    def check(value: object) -> object:
        if type(value) is not list and type(value) is not tuple:
            if arrays.is_ndarray(value):  # a CBOR typed array (D27)
                _length_check(ftype, len(value))  # type: ignore[arg-type]
                whole = None if numeric is None else numeric(value)
                return check(value.tolist()) if whole is None else whole  # type: ignore[attr-defined]
            raise Problem(f"expected {spelled}, got {json_kind(value)}")
        _length_check(ftype, len(value))
        items: list[object] = list(value)
        if items and not fast(items):
            return _each(element, items)
        return items

    return check


def _int_fast(low: int, high: int) -> Callable[[list[object]], bool]:
    def fast(items: list[object]) -> bool:
        if set(map(type, items)) != {int}:
            return False
        ints = cast("list[int]", items)
        return low <= min(ints) and max(ints) <= high

    return fast


def _float32_fast(items: list[object]) -> bool:
    if set(map(type, items)) != {float}:
        return False
    return not any(FLOAT32_MAX < abs(x) < math.inf for x in cast("list[float]", items))


def _types_fast(kind: type) -> Callable[[list[object]], bool]:
    def fast(items: list[object]) -> bool:
        return set(map(type, items)) == {kind}

    return fast


def _never_fast(items: list[object]) -> bool:
    return False


def _octets_checker(ftype: FieldType, as_list: Checker) -> Checker:
    """ROS 2 ``byte[]`` (octets): a list of 0..255, or a byte string (CBOR sends one, D21)."""

    def check(value: object) -> object:
        if isinstance(value, bytes | bytearray):
            _length_check(ftype, len(value))
            return list(value)
        if arrays.is_ndarray(value):  # octets stay a list of ints (D21)
            return as_list(value.tolist())  # type: ignore[attr-defined]
        return as_list(value)

    return check


def array_checker(ftype: FieldType, dialect: Dialect) -> Checker:
    """Build the checker of a primitive array field (not time, not messages).

    ``uint8``/``char`` arrays of any kind become ``bytes`` and accept a base64
    string, an array of ints 0..255 or bytes (D10); ROS 2
    ``byte`` arrays are lists of octets that may come as bytes (CBOR). Other
    arrays become lists; fixed arrays need their exact length, bounded ones at
    most their bound (D9).

    Raises:
        ValueError: the element type is not a scalar primitive.
    """
    element = scalar_checker(ftype.base, dialect, ftype.string_bound)
    if is_bytes_base(ftype.base):
        return _bytes_checker(ftype, element)
    ints = int_range(ftype.base, dialect)
    base = ftype.base
    if ints is not None:
        low, high = ints
        checker = _list_checker(
            ftype,
            element,
            _int_fast(*ints),
            lambda a: arrays.int_array(a, base, low, high),  # type: ignore[arg-type]
        )
        if ftype.base == "byte" and dialect is Dialect.ROS2:
            return _octets_checker(ftype, checker)
        return checker
    if base in ("float32", "float64"):
        fast = _float32_fast if base == "float32" else _types_fast(float)
        return _list_checker(ftype, element, fast, lambda a: arrays.real_array(a, base))  # type: ignore[arg-type]
    if ftype.base == "bool":
        return _list_checker(ftype, element, _types_fast(bool))
    if ftype.string_bound is None:
        return _list_checker(ftype, element, _types_fast(str))
    return _list_checker(ftype, element, _never_fast)


def zero_value(base: str) -> object:
    """The zero of a scalar primitive (0, 0.0, False or "")."""
    if base in ("float32", "float64"):
        return 0.0
    if base == "bool":
        return False
    if base in ("string", "wstring"):
        return ""
    return 0
