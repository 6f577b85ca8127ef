"""The description of a message's fields and constants, independent of its source.

A field's type is a primitive (``int32``, ``string<=8``, ``time`` in ROS 1) or a
message (by canonical name), possibly in an array that is fixed (``[N]``),
bounded (``[<=N]``) or unbounded (``[]``). These records come from the ``.msg``
parser or from a rosbags store and drive both conversion and definition text.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from .names import Dialect

__all__ = [
    "INT_RANGES",
    "PRIMITIVES",
    "ArrayKind",
    "Constant",
    "FieldSpec",
    "FieldType",
    "int_range",
    "is_bytes_base",
]


class ArrayKind(StrEnum):
    """How many values a field holds."""

    NONE = "none"
    FIXED = "fixed"
    BOUNDED = "bounded"
    UNBOUNDED = "unbounded"


#: Inclusive ranges of the integer primitives whose meaning is the same in both dialects.
INT_RANGES: dict[str, tuple[int, int]] = {
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
    "char": (0, 2**8 - 1),
}

#: Every primitive a ``.msg`` file may name (``time``/``duration`` are ROS 1 only).
PRIMITIVES: frozenset[str] = frozenset(
    [*INT_RANGES, "byte", "bool", "float32", "float64", "string", "wstring", "time", "duration"]
)


def int_range(base: str, dialect: Dialect) -> tuple[int, int] | None:
    """The inclusive range of an integer primitive, or None for a non-integer.

    ``byte`` is an unsigned octet in ROS 2 and an int8 in ROS 1 (REF §4.1).
    """
    if base == "byte":
        return INT_RANGES["int8"] if dialect is Dialect.ROS1 else INT_RANGES["uint8"]
    return INT_RANGES.get(base)


def is_bytes_base(base: str) -> bool:
    """Whether arrays of ``base`` are held as ``bytes`` (D10)."""
    return base in ("uint8", "char")


@dataclass(frozen=True, slots=True)
class FieldType:
    """The type of one field.

    Attributes:
        base: a primitive name (``"int32"``, ``"string"``, ``"time"``) or, when
            ``is_message``, the canonical name of a message type.
        is_message: whether ``base`` names a message type.
        array: none, fixed, bounded or unbounded.
        length: element count of a fixed array, upper bound of a bounded one, else None.
        string_bound: the N of ``string<=N``/``wstring<=N``, else None.
    """

    base: str
    is_message: bool = False
    array: ArrayKind = ArrayKind.NONE
    length: int | None = None
    string_bound: int | None = None

    @property
    def element(self) -> FieldType:
        """The type of one element (the field's type without its array part)."""
        return FieldType(self.base, self.is_message, string_bound=self.string_bound)

    def spelled(self, base_text: str | None = None) -> str:
        """The ``.msg`` spelling, ``uint8[<=16]``; ``base_text`` replaces the base name."""
        text = base_text if base_text is not None else self.base
        if self.string_bound is not None:
            text += f"<={self.string_bound}"
        if self.array is ArrayKind.FIXED:
            text += f"[{self.length}]"
        elif self.array is ArrayKind.BOUNDED:
            text += f"[<={self.length}]"
        elif self.array is ArrayKind.UNBOUNDED:
            text += "[]"
        return text


@dataclass(frozen=True, slots=True)
class FieldSpec:
    """One field of a message, in declaration order.

    Attributes:
        name: the field name.
        type: its type.
        default: the default written in the definition (``float64 w 1``), in the
            internal form (D7); None when the text has none, in
            which case the type's zero value applies.
    """

    name: str
    type: FieldType
    default: object = None


@dataclass(frozen=True, slots=True)
class Constant:
    """A constant of a message (``uint8 RED=1``); not part of message values.

    Attributes:
        name: the constant's name.
        type: its primitive type name.
        value: its value (int, float, bool or str).
    """

    name: str
    type: str
    value: object
