"""Compile a message type into a JSON converter and a default builder.

Each message type is compiled once into two closures: ``convert(value, path,
ctx)`` checks a JSON-decoded value and returns the internal form, and
``default(now)`` builds the default value. The plan of a type is a tuple of
``(field name, simple?, checker, default)`` built from its field specs; a
*simple* checker takes only the value (primitives and primitive arrays), the
others also take the JSON path and the conversion context (times, messages).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

from rwt_protocol.errors import FieldError

from .names import Dialect
from .primitives import Problem, array_checker, json_kind, scalar_checker, zero_value
from .spec import ArrayKind, FieldSpec, FieldType, is_bytes_base

__all__ = [
    "Context",
    "ConvertFn",
    "DefaultFn",
    "compile_message",
    "header_stamp",
    "is_header",
    "is_time_type",
    "time_keys",
    "time_parts",
    "time_value",
]


class Context:
    """State of one conversion: the clock and the fields the input omitted.

    A plain slotted class: one is built per converted message, and this is
    the cheapest to build (the publish hot path, B14).

    Attributes:
        now: wall-clock seconds since the epoch, for ``"now"`` and header stamps.
        missing: JSON paths of omitted fields, in the order met (D7).
    """

    __slots__ = ("missing", "now")

    def __init__(self, now: float) -> None:
        self.now = now
        self.missing: list[str] = []


ConvertFn = Callable[[object, str, Context], object]
DefaultFn = Callable[[float | None], object]
#: How a compiled field plan finds the compiled form of a nested message type.
Lookup = Callable[[str], tuple[ConvertFn, DefaultFn]]

_MISSING = object()
_TIME_NAMES = {
    "builtin_interfaces/msg/Time": True,
    "builtin_interfaces/msg/Duration": False,
    "time": True,
    "duration": False,
}
_HEADER_NAMES = frozenset({"std_msgs/msg/Header", "std_msgs/Header"})


def is_time_type(ftype: FieldType) -> bool:
    """Whether a field holds times or durations (either dialect's spelling)."""
    return ftype.base in _TIME_NAMES


def is_header(name: str) -> bool:
    """Whether ``name`` is the canonical name of ``std_msgs/Header`` (D8)."""
    return name in _HEADER_NAMES


def time_keys(dialect: Dialect) -> tuple[str, str]:
    """The second and nanosecond keys of a time value in ``dialect`` (REF §4.1)."""
    return ("secs", "nsecs") if dialect is Dialect.ROS1 else ("sec", "nanosec")


def time_value(now: float, dialect: Dialect) -> dict[str, object]:
    """Split ``now`` (seconds since the epoch) into the dialect's time object."""
    sec_key, nsec_key = time_keys(dialect)
    seconds = math.floor(now)
    nanos = min(round((now - seconds) * 1e9), 999_999_999)
    return {sec_key: int(seconds), nsec_key: int(nanos)}


def time_parts(value: object) -> tuple[int, int] | None:
    """``(seconds, nanoseconds)`` of a time value in either dialect, or None.

    Reads ``{sec, nanosec}`` (ROS 2) and ``{secs, nsecs}`` (ROS 1), a missing
    part being 0 (REF §4.1); None when ``value`` is not such a dict of ints.
    """
    if not isinstance(value, Mapping):
        return None
    sec = value.get("sec", value.get("secs", 0))
    nsec = value.get("nanosec", value.get("nsecs", 0))
    if type(sec) is int and type(nsec) is int:
        return sec, nsec
    return None


def header_stamp(msg: Mapping[str, object]) -> tuple[int, int] | None:
    """``time_parts`` of a message's ``header.stamp``; None without one."""
    header = msg.get("header")
    return time_parts(header.get("stamp")) if isinstance(header, Mapping) else None


def _time_ranges(is_time: bool, dialect: Dialect) -> tuple[str, str]:
    if dialect is Dialect.ROS1:
        return ("uint32", "uint32") if is_time else ("int32", "int32")
    return ("int32", "uint32")


def _time_checker(label: str, is_time: bool, dialect: Dialect) -> ConvertFn:
    """Accept ``{sec, nanosec}``, ``{secs, nsecs}`` and, for times, ``"now"`` (REF §4.3)."""
    sec_key, nsec_key = time_keys(dialect)
    sec_type, nsec_type = _time_ranges(is_time, dialect)
    parts = (
        (sec_key, ("sec", "secs"), scalar_checker(sec_type, dialect)),
        (nsec_key, ("nanosec", "nsecs"), scalar_checker(nsec_type, dialect)),
    )

    def check(value: object, path: str, ctx: Context) -> object:
        if type(value) is not dict:
            if is_time and value == "now":
                return time_value(ctx.now, dialect)
            raise FieldError(path, f"expected object (type {label}), got {json_kind(value)}")
        out: dict[str, object] = {}
        found = 0
        for key, spellings, checker in parts:
            given = [s for s in spellings if s in value]
            if len(given) > 1:
                raise FieldError(path, f"expected one of {given[0]!r} and {given[1]!r}, got both")
            if not given:
                out[key] = 0
                ctx.missing.append(f"{path}.{key}")
                continue
            found += 1
            try:
                out[key] = checker(value[given[0]])
            except Problem as problem:
                raise FieldError(f"{path}.{given[0]}", problem.problem) from None
        if found != len(value):
            _raise_unknown(value, ("sec", "secs", "nanosec", "nsecs"), path)
        return out

    return check


def _raise_unknown(value: dict[str, object], known: tuple[str, ...], path: str) -> None:
    """Raise for the first key of ``value`` not in ``known`` (the caller counted one)."""
    key = next(key for key in value if key not in known)
    raise FieldError(path, f"unknown field {key!r}")


def _const(value: object) -> DefaultFn:
    return lambda now: value


def _array_default(ftype: FieldType, element: DefaultFn) -> DefaultFn:
    if ftype.array is not ArrayKind.FIXED:
        return lambda now: []
    count = ftype.length or 0
    return lambda now: [element(now) for _ in range(count)]


def _primitive_default(spec: FieldSpec) -> DefaultFn:
    ftype = spec.type
    if spec.default is not None:
        if isinstance(spec.default, list):
            written = spec.default
            return lambda now: list(written)
        return _const(spec.default)
    if ftype.array is ArrayKind.NONE:
        return _const(zero_value(ftype.base))
    if is_bytes_base(ftype.base):
        return _const(bytes(ftype.length or 0) if ftype.array is ArrayKind.FIXED else b"")
    zero = zero_value(ftype.base)
    return _array_default(ftype, lambda now: zero)


def _element_array(ftype: FieldType, element: ConvertFn) -> ConvertFn:
    """Wrap an element converter (times, messages) into an array converter."""
    spelled = ftype.spelled()

    def check(value: object, path: str, ctx: Context) -> object:
        if type(value) is not list and type(value) is not tuple:
            raise FieldError(path, f"expected {spelled}, got {json_kind(value)}")
        count = len(value)
        if ftype.array is ArrayKind.FIXED and count != ftype.length:
            raise FieldError(path, f"expected {ftype.length} elements, got {count}")
        if ftype.array is ArrayKind.BOUNDED and count > (ftype.length or 0):
            raise FieldError(path, f"expected at most {ftype.length} elements, got {count}")
        return [element(item, f"{path}[{i}]", ctx) for i, item in enumerate(value)]

    return check


PlanEntry = tuple[str, bool, Callable[..., object], DefaultFn]


def _plan_entry(spec: FieldSpec, dialect: Dialect, lookup: Lookup, header: bool) -> PlanEntry:
    ftype = spec.type
    if is_time_type(ftype):
        is_time = _TIME_NAMES[ftype.base]
        element: ConvertFn = _time_checker(ftype.base, is_time, dialect)
        zero_time = dict.fromkeys(time_keys(dialect), 0)
        if header and spec.name == "stamp" and ftype.array is ArrayKind.NONE:
            # D8: an omitted stamp is the current time.
            elem_default: DefaultFn = lambda now: (  # noqa: E731
                dict(zero_time) if now is None else time_value(now, dialect)
            )
        else:
            elem_default = lambda now: dict(zero_time)  # noqa: E731
    elif ftype.is_message:
        element, elem_default = lookup(ftype.base)
    elif ftype.array is ArrayKind.NONE:
        return (
            spec.name,
            True,
            scalar_checker(ftype.base, dialect, ftype.string_bound),
            _primitive_default(spec),
        )
    else:
        return (spec.name, True, array_checker(ftype, dialect), _primitive_default(spec))
    if ftype.array is ArrayKind.NONE:
        return (spec.name, False, element, elem_default)
    return (spec.name, False, _element_array(ftype, element), _array_default(ftype, elem_default))


def compile_message(
    name: str, fields: tuple[FieldSpec, ...], dialect: Dialect, lookup: Lookup
) -> tuple[ConvertFn, DefaultFn]:
    """Compile the converter and default builder of one message type.

    Args:
        name: canonical type name, named in "expected object (type ...)" texts.
        fields: the type's fields in declaration order.
        dialect: decides time keys and ranges.
        lookup: gives the compiled pair of a nested message type by canonical name.

    Returns:
        ``(convert, default)``. ``convert(value, path, ctx)`` returns a dict with
        every field in declaration order, fills omitted fields with their
        defaults (recording their paths in ``ctx.missing``) and raises
        ``FieldError`` for a non-object, an unknown key or a bad value
        (D7-D10). ``default(now)`` builds the default value;
        header stamps are ``now`` when it is given (D8).
    """
    if name in _TIME_NAMES:
        is_time = _TIME_NAMES[name]
        zero = dict.fromkeys(time_keys(dialect), 0)
        return _time_checker(name, is_time, dialect), lambda now: dict(zero)
    plan = tuple(_plan_entry(spec, dialect, lookup, is_header(name)) for spec in fields)

    def default(now: float | None) -> object:
        return {key: make(now) for key, _, _, make in plan}

    return _message_converter(name, plan), default


def _message_converter(name: str, plan: tuple[PlanEntry, ...]) -> ConvertFn:
    """The converter of a message whose fields follow ``plan`` (see ``compile_message``)."""
    known = tuple(key for key, _, _, _ in plan)

    def convert(value: object, path: str, ctx: Context) -> object:
        if type(value) is not dict:
            raise FieldError(path, f"expected object (type {name}), got {json_kind(value)}")
        out: dict[str, object] = {}
        found = 0
        for key, simple, checker, default in plan:
            item = value.get(key, _MISSING)
            if item is _MISSING:
                out[key] = default(ctx.now)
                ctx.missing.append(f"{path}.{key}")
                continue
            found += 1
            if simple:
                try:
                    out[key] = checker(item)
                except Problem as problem:
                    raise FieldError(f"{path}.{key}{problem.suffix}", problem.problem) from None
            else:
                out[key] = checker(item, f"{path}.{key}", ctx)
        if found != len(value):
            _raise_unknown(value, known, path)
        return out

    return convert
