"""Frame patterns of the conformance cases: substitution and matching.

Case data is TOML, which has no ``null``; sentinels written as strings stand in
for what TOML cannot say and for "any value of this kind":

- in frames to send and in patterns: ``"<null>"`` is JSON ``null``;
  ``"${name}"`` is the variable ``name`` (the whole string keeps the variable's
  type; inside a longer string it is spliced in as text); ``"${pad:N}"`` is N
  letters ``A`` (large frames without large files; ``A`` is also valid base64).
- in patterns only: ``"<any>"`` (present, any value), ``"<absent>"`` (the key
  must be missing), ``"<str>"``, ``"<int>"``, ``"<number>"``, ``"<bool>"``,
  ``"<object>"``, ``"<array>"``, ``"<bytes>"`` (a CBOR byte string),
  ``"<bytes:HEX>"`` (a byte string holding exactly these bytes, in hex),
  ``"<positive>"`` (a number above 0),
  ``"<re:REGEX>"`` (a string matching REGEX,
  searched), ``"<capture:name>"`` (any value, remembered as ``name``).

An object pattern matches an object having at least the pattern's keys (extra
keys are fine: spec 1 lets servers add fields); an array pattern matches an
array of the same length element by element; numbers compare by value.
"""

from __future__ import annotations

import math
import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["JsonValue", "describe", "match", "substitute"]

JsonValue = object
"""A decoded JSON (or CBOR) value: dict, list, str, int, float, bool, None or bytes."""

NULL = "<null>"
_VARIABLE = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*|pad:[0-9]+)\}")
_KINDS: dict[str, tuple[type, ...]] = {
    "<str>": (str,),
    "<int>": (int,),
    "<number>": (int, float),
    "<bool>": (bool,),
    "<object>": (dict,),
    "<array>": (list,),
    "<bytes>": (bytes,),
}


def substitute(value: JsonValue, variables: Mapping[str, JsonValue]) -> JsonValue:
    """Replace ``"<null>"`` and ``"${name}"`` in a frame or pattern, recursively.

    Raises:
        KeyError: a ``${name}`` that is not defined.
    """
    if isinstance(value, str):
        if value == NULL:
            return None
        whole = _VARIABLE.fullmatch(value)
        if whole is not None:
            return _lookup(whole.group(1), variables)
        return _VARIABLE.sub(lambda m: str(_lookup(m.group(1), variables)), value)
    if isinstance(value, dict):
        return {key: substitute(item, variables) for key, item in value.items()}
    if isinstance(value, list):
        return [substitute(item, variables) for item in value]
    return value


def _lookup(name: str, variables: Mapping[str, JsonValue]) -> JsonValue:
    if name.startswith("pad:"):
        return "A" * int(name[len("pad:") :])
    return variables[name]


def match(
    pattern: JsonValue, actual: JsonValue, captures: dict[str, JsonValue], path: str = "$"
) -> str | None:
    """Check ``actual`` against ``pattern`` (already substituted).

    Args:
        pattern: the expected shape, with sentinels (module docstring).
        actual: the received value.
        captures: receives ``<capture:name>`` values; written only on success
            of the enclosing call.
        path: JSON path of ``actual``, for the mismatch text.

    Returns:
        None when it matches, else a short text naming the first difference.
    """
    found: dict[str, JsonValue] = {}
    problem = _match(pattern, actual, found, path)
    if problem is None:
        captures.update(found)
    return problem


def _match(
    pattern: JsonValue, actual: JsonValue, found: dict[str, JsonValue], path: str
) -> str | None:
    if isinstance(pattern, str) and pattern.startswith("<") and pattern.endswith(">"):
        return _match_sentinel(pattern, actual, found, path)
    if isinstance(pattern, dict):
        return _match_object(pattern, actual, found, path)
    if isinstance(pattern, list):
        return _match_array(pattern, actual, found, path)
    return _match_scalar(pattern, actual, path)


def _match_object(
    pattern: dict[str, JsonValue], actual: JsonValue, found: dict[str, JsonValue], path: str
) -> str | None:
    if not isinstance(actual, dict):
        return f"{path}: expected an object, got {describe(actual)}"
    for key, sub in pattern.items():
        where = f"{path}.{key}"
        if sub == "<absent>":
            if key in actual:
                return f"{where}: expected no such key, got {describe(actual[key])}"
            continue
        if key not in actual:
            return f"{where}: missing"
        problem = _match(sub, actual[key], found, where)
        if problem is not None:
            return problem
    return None


def _match_array(
    pattern: list[JsonValue], actual: JsonValue, found: dict[str, JsonValue], path: str
) -> str | None:
    if not isinstance(actual, list):
        return f"{path}: expected an array, got {describe(actual)}"
    if len(pattern) != len(actual):
        return f"{path}: expected {len(pattern)} items, got {len(actual)}"
    for index, (sub, item) in enumerate(zip(pattern, actual, strict=True)):
        problem = _match(sub, item, found, f"{path}[{index}]")
        if problem is not None:
            return problem
    return None


def _match_scalar(pattern: JsonValue, actual: JsonValue, path: str) -> str | None:
    if isinstance(pattern, bool) or isinstance(actual, bool):
        same = isinstance(pattern, bool) and isinstance(actual, bool) and pattern == actual
    elif isinstance(pattern, int | float) and isinstance(actual, int | float):
        same = pattern == actual or (
            isinstance(pattern, float) and math.isnan(pattern) and math.isnan(actual)
        )
    else:
        same = type(pattern) is type(actual) and pattern == actual
    return None if same else f"{path}: expected {describe(pattern)}, got {describe(actual)}"


def _match_sentinel(
    pattern: str, actual: JsonValue, found: dict[str, JsonValue], path: str
) -> str | None:
    if pattern == "<any>":
        return None
    if pattern == NULL:
        return None if actual is None else f"{path}: expected null, got {describe(actual)}"
    if pattern == "<positive>":
        if isinstance(actual, int | float) and not isinstance(actual, bool) and actual > 0:
            return None
        return f"{path}: expected a number above 0, got {describe(actual)}"
    if pattern.startswith("<bytes:"):
        expected = pattern[len("<bytes:") : -1]
        if isinstance(actual, bytes) and actual.hex() == expected.lower():
            return None
        return f"{path}: expected the bytes {expected}, got {describe(actual)}"
    if pattern.startswith("<capture:"):
        found[pattern[len("<capture:") : -1]] = actual
        return None
    if pattern.startswith("<re:"):
        regex = pattern[len("<re:") : -1]
        if isinstance(actual, str) and re.search(regex, actual):
            return None
        return f"{path}: expected text matching {regex!r}, got {describe(actual)}"
    kinds = _KINDS.get(pattern)
    if kinds is None:  # not a sentinel after all: a literal string in angle brackets
        return _match_scalar(pattern, actual, path)
    if isinstance(actual, kinds) and (pattern == "<bool>" or not isinstance(actual, bool)):
        return None
    return f"{path}: expected {pattern[1:-1]}, got {describe(actual)}"


def describe(value: JsonValue, limit: int = 60) -> str:
    """Show a value briefly for a mismatch text.

    ``repr`` keeps it printable (lone surrogates and control characters come out
    escaped); a value holding an integer too long for ``repr`` (over Python's
    4300 digits, a CBOR bignum) is named, not shown.
    """
    if isinstance(value, bytes):
        text = f"<{len(value)} bytes{': ' + value.hex() if len(value) <= 16 else ''}>"
    else:
        try:
            text = repr(value)
        except ValueError:  # int over sys.get_int_max_str_digits()
            text = "<a value with an integer too long to show>"
    return text if len(text) <= limit else text[: limit - 3] + "..."
