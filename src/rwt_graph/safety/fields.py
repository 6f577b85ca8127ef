"""Bounded field paths: checked against a message type once, then applied to each message.

A path names a numeric field through nested messages (``linear.x``), an element of
an array (``position[0]``) or every element of one (``position[*]``, ``points[*].x``).
``compile_field`` checks it against the topic's type at start (a field the type lacks,
or a field that is not a number, is refused, D66); ``BoundedField.values`` finds the
values of a message, ``replaced`` clamps them without touching the message the
client gave (it may be shared). ``non_finite`` finds a NaN or an infinity in any
float field of a message: on a bounded topic that is a violation whatever the bounds.

Messages are in the graph's internal form (dicts; arrays as lists, tuples or numpy
arrays, ``uint8[]`` as bytes); nothing here imports numpy: an array a client sent as
one is read through its own methods.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..types.spec import INT_RANGES, ArrayKind, is_bytes_base

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from ..types import MessageType

__all__ = ["BoundedField", "compile_field", "non_finite", "replaced"]

EVERY = -1
"""An index meaning every element (``[*]``)."""

_NUMERIC = frozenset({*INT_RANGES, "byte", "float32", "float64"})
_FLOATS = frozenset({"float32", "float64"})
_SEGMENT = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)(?:\[(\d+|\*)\])?$")

Path = tuple[str | int, ...]
"""A concrete place in a message: field names and element indices."""


@dataclass(frozen=True)
class BoundedField:
    """One bound of a topic: a numeric field (or elements) and its inclusive range.

    Attributes:
        text: the path as the rules write it (``linear.x``).
        steps: ``(field name, index)`` per segment; index None for none, ``EVERY`` for ``[*]``.
        integer: the field holds integers (a clamp gives a whole number).
        low, high: the bound, in the field's units.
    """

    text: str
    steps: tuple[tuple[str, int | None], ...]
    integer: bool
    low: float
    high: float

    @property
    def bound(self) -> str:
        """``[-0.5, 0.5]``, for messages."""
        return f"[{self.low:g}, {self.high:g}]"

    def values(self, msg: object) -> Iterator[tuple[Path, object]]:
        """Each value the path names in ``msg``, with its place; absent ones are skipped.

        An element of a numpy array (a CBOR client's typed array) is given as a Python
        number, so that the audit and the client's warning show it as a JSON client's.
        """
        yield from _walk(msg, self.steps, 0, ())

    def clamp(self, value: float) -> float | int:
        """``value`` moved into the bound (whole numbers for an integer field)."""
        if self.integer:
            return min(max(int(value), math.ceil(self.low)), math.floor(self.high))
        return min(max(float(value), self.low), self.high)


def compile_field(
    msgtype: MessageType, text: str, low: float, high: float, lookup: Callable[[str], MessageType]
) -> BoundedField:
    """Check that ``text`` names a numeric field of ``msgtype``.

    Args:
        msgtype: the topic's type.
        text: the path (``linear.x``, ``position[0]``, ``points[*].x``).
        low: the bound's minimum.
        high: its maximum.
        lookup: finds a nested message type by its name (the registry's ``message``).

    Raises:
        ValueError: no such field, an array named without an index, a field that
            is not a number (bool, string, a message), or ``uint8[]`` (held as bytes).
    """
    segments = text.split(".")
    steps: list[tuple[str, int | None]] = []
    current = msgtype
    for number, segment in enumerate(segments, 1):
        found = _SEGMENT.match(segment)
        if found is None:
            raise ValueError(f"{text!r}: {segment!r} is not a field (name, name[N], name[*])")
        name, index_text = found[1], found[2]
        spec = next((each for each in current.fields if each.name == name), None)
        if spec is None:
            raise ValueError(f"{current.name} has no field {name!r} ({text!r})")
        kind = spec.type
        index = None if index_text is None else EVERY if index_text == "*" else int(index_text)
        if kind.array is ArrayKind.NONE and index is not None:
            raise ValueError(f"{text!r}: {name} is not an array")
        if kind.array is not ArrayKind.NONE and index is None:
            raise ValueError(
                f"{text!r}: {name} is an array: name an element, {name}[0], or all, {name}[*]"
            )
        fixed = kind.array is ArrayKind.FIXED and kind.length is not None
        if fixed and index is not None and index >= (kind.length or 0):
            raise ValueError(f"{text!r}: {name} has {kind.length} elements")
        steps.append((name, index))
        last = number == len(segments)
        if not last:
            if not kind.is_message:
                raise ValueError(f"{text!r}: {name} is a {kind.base}, not a message")
            current = lookup(kind.base)
            continue
        if kind.is_message or kind.base not in _NUMERIC:
            raise ValueError(f"{text!r}: {name} is a {kind.spelled()}, not a number field")
        if kind.array is not ArrayKind.NONE and is_bytes_base(kind.base):
            raise ValueError(f"{text!r}: {kind.spelled()} is held as bytes: not bounded")
    integer = kind.base not in _FLOATS
    return BoundedField(text, tuple(steps), integer, low, high)


def _walk(
    node: object, steps: tuple[tuple[str, int | None], ...], at: int, path: Path
) -> Iterator[tuple[Path, object]]:
    if at == len(steps):  # a numpy array's element as a Python number, as JSON's are
        item = getattr(node, "item", None)
        yield path, node if item is None else item()
        return
    if not isinstance(node, dict):
        return
    name, index = steps[at]
    value = node.get(name)
    if value is None:
        return
    if index is None:
        yield from _walk(value, steps, at + 1, (*path, name))
        return
    try:
        count = len(value)
    except TypeError:
        return
    indices = range(count) if index == EVERY else (index,) if index < count else ()
    for each in indices:
        yield from _walk(value[each], steps, at + 1, (*path, name, each))


def replaced(msg: dict[str, object], changes: list[tuple[Path, object]]) -> dict[str, object]:
    """``msg`` with each ``(path, value)`` set, copying only the containers on the way.

    The message given is never changed (a client's decoded message, or an array a
    CBOR client sent, which is read-only).
    """
    copied: dict[int, object] = {}
    top = dict(msg)
    copied[id(msg)] = top
    for path, value in changes:
        node: object = top
        for key in path[:-1]:
            child = node[key]  # type: ignore[index]
            copy = copied.get(id(child))
            if copy is None:
                copy = copied[id(child)] = _copy(child)
                copied[id(copy)] = copy  # the next change in it finds it: one copy, not one each
                node[key] = copy  # type: ignore[index]
            node = copy
        node[path[-1]] = value  # type: ignore[index]
    return top


def _copy(container: object) -> object:
    if isinstance(container, dict):
        return dict(container)
    if isinstance(container, list | tuple):
        return list(container)
    copy = getattr(container, "copy", None)  # a numpy array (a CBOR client's typed array)
    if copy is None:
        raise TypeError(f"cannot copy a {type(container).__name__}")
    return copy()


_FloatPlan = tuple[tuple[str, bool, "MessageType | None"], ...]


def non_finite(
    msgtype: MessageType,
    msg: object,
    lookup: Callable[[str], MessageType],
    plans: dict[str, _FloatPlan],
) -> tuple[str, object] | None:
    """The first NaN or infinity in a float field of ``msg``: ``(path, value)``, or None.

    ``plans`` caches, per type name, which fields hold floats (or messages that do).
    """
    return _first_bad(msgtype, msg, lookup, plans, "")


def _first_bad(
    msgtype: MessageType,
    msg: object,
    lookup: Callable[[str], MessageType],
    plans: dict[str, _FloatPlan],
    prefix: str,
) -> tuple[str, object] | None:
    if not isinstance(msg, dict):
        return None
    for name, array, nested in _plan(msgtype, lookup, plans):
        value = msg.get(name)
        if value is None:
            continue
        where = f"{prefix}{name}"
        if nested is not None:
            items = value if array else (value,)
            for number, item in enumerate(items):
                place = f"{where}[{number}]." if array else f"{where}."
                found = _first_bad(nested, item, lookup, plans, place)
                if found is not None:
                    return found
        elif array:
            element = _bad_element(value)
            if element is not None:
                return f"{where}[{element[0]}]", element[1]
        elif isinstance(value, float) and not math.isfinite(value):
            return where, value
    return None


def _bad_element(values: object) -> tuple[int, object] | None:
    """The first non-finite element of a float array (a list, or a numpy array), or None."""
    finite = getattr(values, "__array__", None)
    if finite is not None:  # numpy's own check: no Python loop over a large array
        import numpy as np  # noqa: PLC0415  # loaded already: the array is numpy's

        bad = np.flatnonzero(~np.isfinite(np.asarray(values, dtype=np.float64)))
        return None if bad.size == 0 else (int(bad[0]), float(np.asarray(values)[bad[0]]))
    if not isinstance(values, list | tuple):
        return None
    try:
        if all(map(math.isfinite, values)):
            return None
    except TypeError:
        return None
    return next((index, value) for index, value in enumerate(values) if not math.isfinite(value))


def _plan(
    msgtype: MessageType, lookup: Callable[[str], MessageType], plans: dict[str, _FloatPlan]
) -> _FloatPlan:
    """The fields of ``msgtype`` that hold floats, or messages that do: ``(name, array, type)``."""
    plan = plans.get(msgtype.name)
    if plan is not None:
        return plan
    plans[msgtype.name] = ()  # a type that contains itself stops here
    found: list[tuple[str, bool, MessageType | None]] = []
    for spec in msgtype.fields:
        array = spec.type.array is not ArrayKind.NONE
        if spec.type.is_message:
            nested = lookup(spec.type.base)
            if _plan(nested, lookup, plans):
                found.append((spec.name, array, nested))
        elif spec.type.base in _FLOATS:
            found.append((spec.name, array, None))
    plan = plans[msgtype.name] = tuple(found)
    return plan
