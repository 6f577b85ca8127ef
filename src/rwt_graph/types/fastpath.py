"""A generated converter for messages that need nothing but type checks (B14).

Most published messages carry every field, each of the right JSON kind. For
those, conversion is a handful of ``type(v) is ...`` tests and one dict; the
general converter (``convert.compile_message``) pays for what such messages
never need: a ``Context``, the field plan's loop, default builders, error
paths. So each message type also gets a *fast* function, generated as Python
source once per type (as ``dataclasses`` does for ``__init__``), that either
returns the internal form or ``None``; ``None`` sends the value down the
general path, which fills defaults, converts ints to floats, accepts the other
dialect's time keys and gives the error texts (D7-D10).

Whatever the fast function returns, the general converter would have returned
too: it only accepts values the general path keeps unchanged (strings, ints
in range, floats in range, bools), times in the dialect's own keys, arrays
through the same checkers, and nested messages through their own fast
function.
"""

from __future__ import annotations

from collections.abc import Callable

from .names import Dialect
from .primitives import FLOAT32_MAX, Checker, Problem, array_checker
from .spec import ArrayKind, FieldSpec, int_range

__all__ = ["FastFn", "compile_fast"]

FastFn = Callable[[object], "dict[str, object] | None"]
#: Finds the fast function of a nested message type (None: that type has none).
FastLookup = Callable[[str], "FastFn | None"]

_TIME_BASES = {
    "builtin_interfaces/msg/Time": True,
    "builtin_interfaces/msg/Duration": False,
    "time": True,
    "duration": False,
}


class _Source:
    """The generated function's lines and the objects its code refers to."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.names: dict[str, object] = {"Problem": Problem, "_dict": dict, "_list": list}

    def bind(self, prefix: str, value: object) -> str:
        name = f"{prefix}{len(self.names)}"
        self.names[name] = value
        return name


def _int_test(var: str, bounds: tuple[int, int]) -> str:
    low, high = bounds
    return f"type({var}) is int and {low} <= {var} <= {high}"


def _scalar_test(spec: FieldSpec, var: str, dialect: Dialect) -> str | None:
    """A Python expression true when ``var`` is already in the internal form, or None."""
    base = spec.type.base
    bounds = int_range(base, dialect)
    if bounds is not None:
        return _int_test(var, bounds)
    if base == "float64":
        return f"type({var}) is float"
    if base == "float32":  # NaN and infinities take the general path
        return f"type({var}) is float and -{FLOAT32_MAX!r} <= {var} <= {FLOAT32_MAX!r}"
    if base == "bool":
        return f"({var} is True or {var} is False)"
    if base in ("string", "wstring") and spec.type.string_bound is None:
        return f"type({var}) is str"
    return None  # bounded strings: the general path counts characters


def _time_lines(src: _Source, var: str, is_time: bool, dialect: Dialect) -> bool:
    """Lines that rebuild a time given in the dialect's own keys into ``var``."""
    sec_key, nsec_key = ("secs", "nsecs") if dialect is Dialect.ROS1 else ("sec", "nanosec")
    if dialect is Dialect.ROS1:
        sec_range = (0, 2**32 - 1) if is_time else (-(2**31), 2**31 - 1)
        nsec_range = sec_range
    else:
        sec_range, nsec_range = (-(2**31), 2**31 - 1), (0, 2**32 - 1)
    src.lines += [
        f"    if type({var}) is not _dict or len({var}) != 2: return None",
        f"    s = {var}.get({sec_key!r}); n = {var}.get({nsec_key!r})",
        f"    if not ({_int_test('s', sec_range)} and {_int_test('n', nsec_range)}): return None",
        f"    {var} = {{{sec_key!r}: s, {nsec_key!r}: n}}",
    ]
    return True


def _field_lines(
    src: _Source, spec: FieldSpec, var: str, dialect: Dialect, lookup: FastLookup
) -> bool:
    """Append the lines that check ``var`` and leave its internal form in it."""
    ftype = spec.type
    time_kind = _TIME_BASES.get(ftype.base)
    if ftype.array is ArrayKind.NONE:
        if time_kind is not None:
            return _time_lines(src, var, time_kind, dialect)
        if ftype.is_message:
            inner = lookup(ftype.base)
            if inner is None:
                return False
            fn = src.bind("m", inner)
            src.lines.append(f"    {var} = {fn}({var})")
            src.lines.append(f"    if {var} is None: return None")
            return True
        test = _scalar_test(spec, var, dialect)
        if test is None:
            return False
        src.lines.append(f"    if not ({test}): return None")
        return True
    if time_kind is not None:
        return False  # arrays of times: rare, the general path handles them
    if ftype.is_message:
        inner = lookup(ftype.base)
        if inner is None:
            return False
        return _message_array_lines(src, spec, var, inner)
    checker: Checker = array_checker(ftype, dialect)
    fn = src.bind("a", checker)
    src.lines += [
        "    try:",
        f"        {var} = {fn}({var})",
        "    except Problem:",
        "        return None",
    ]
    return True


def _message_array_lines(src: _Source, spec: FieldSpec, var: str, inner: FastFn) -> bool:
    ftype = spec.type
    fn = src.bind("m", inner)
    src.lines.append(f"    if type({var}) is not _list: return None")
    if ftype.array is ArrayKind.FIXED:
        src.lines.append(f"    if len({var}) != {ftype.length}: return None")
    elif ftype.array is ArrayKind.BOUNDED:
        src.lines.append(f"    if len({var}) > {ftype.length}: return None")
    src.lines += [
        f"    {var} = [{fn}(item) for item in {var}]",
        f"    if None in {var}: return None",
    ]
    return True


def compile_fast(
    name: str, fields: tuple[FieldSpec, ...], dialect: Dialect, lookup: FastLookup
) -> FastFn | None:
    """Generate the fast converter of one message type.

    Args:
        name: canonical type name (names the generated function, for profiles).
        fields: the type's fields in declaration order.
        dialect: decides time keys and integer ranges.
        lookup: gives the fast function of a nested message type, or None.

    Returns:
        ``fast(value)``: the internal form of ``value`` (a new dict with every
        field in declaration order) when ``value`` is a dict holding exactly
        the type's fields, each already in its internal form; otherwise None.
        Never raises. Returns None instead of a function when a field's kind
        always needs the general path (bounded strings, arrays of times) or a
        field name is not a Python identifier.
    """
    if name in _TIME_BASES or not all(spec.name.isidentifier() for spec in fields):
        return None
    src = _Source()
    keys = [spec.name for spec in fields]
    src.lines.append(f"    if type(value) is not _dict or len(value) != {len(keys)}: return None")
    if keys:
        src.lines.append("    try:")
        src.lines += [f"        f{i} = value[{key!r}]" for i, key in enumerate(keys)]
        src.lines += ["    except KeyError:", "        return None"]
    for i, spec in enumerate(fields):
        if not _field_lines(src, spec, f"f{i}", dialect, lookup):
            return None
    built = ", ".join(f"{key!r}: f{i}" for i, key in enumerate(keys))
    src.lines.append(f"    return {{{built}}}")
    label = "".join(c if c.isalnum() else "_" for c in name)
    code = f"def fast_{label}(value):\n" + "\n".join(src.lines) + "\n"
    namespace: dict[str, object] = dict(src.names)
    exec(compile(code, f"<rwt fast converter {name}>", "exec"), namespace)
    return namespace[f"fast_{label}"]  # type: ignore[return-value]
