"""Type strings: the dialect, their parsing and their canonical spelling.

A type string names a message, service or action as ``pkg/Type`` or
``pkg/<kind>/Type``; both forms mean the same type (D5).
Redundant, leading and trailing slashes are ignored; everything else listed as
invalid in REF §4.6 raises :class:`InvalidTypeNameError`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum
from typing import Literal

from rwt_protocol.errors import GraphError

__all__ = [
    "Dialect",
    "InvalidTypeNameError",
    "Kind",
    "TypeName",
    "UnknownTypeError",
    "parse_type_name",
]

Kind = Literal["msg", "srv", "action"]

_KIND_WORDS: dict[str, str] = {"msg": "message", "srv": "service", "action": "action"}
_IDENT = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")


class Dialect(StrEnum):
    """Which ROS generation the server speaks (D6).

    ``ROS2`` uses ``sec``/``nanosec`` times and ``pkg/msg/Type`` names; ``ROS1``
    uses ``secs``/``nsecs``, ``pkg/Type`` names, a ``seq`` in ``std_msgs/Header``,
    ``byte`` as int8 and ``char`` as uint8.
    """

    ROS2 = "ros2"
    ROS1 = "ros1"


class InvalidTypeNameError(GraphError):
    """A type string is malformed (REF §4.6).

    Args:
        name: the string as the peer sent it.
        kind: what was asked for, ``"msg"``, ``"srv"`` or ``"action"``.
    """

    def __init__(self, name: str, kind: Kind = "msg") -> None:
        super().__init__(
            f"{name!r} is not a valid type name (expected pkg/Type or pkg/{kind}/Type)"
        )
        self.name = name
        self.kind = kind


class UnknownTypeError(GraphError):
    """A well-formed type string names no known type (REF §4.6).

    Args:
        name: canonical name of the missing type.
        kind: ``"msg"``, ``"srv"`` or ``"action"``.
        package_known: whether any type of that package is known; when not, the
            text says so (the reference distinguishes "no such package" from
            "no such class").
    """

    def __init__(self, name: str, kind: Kind = "msg", *, package_known: bool = True) -> None:
        text = f"unknown {_KIND_WORDS[kind]} type {name!r}"
        if not package_known:
            text += f" (no package {name.split('/', 1)[0]!r})"
        super().__init__(text)
        self.name = name
        self.kind = kind
        self.package_known = package_known


@dataclass(frozen=True, slots=True)
class TypeName:
    """A parsed type string.

    Attributes:
        package: the ROS package, ``std_msgs``.
        kind: the interface kind, ``msg``, ``srv`` or ``action``; for a message it
            may be ``srv`` or ``action`` when the name is one of the generated
            parts (``pkg/srv/AddTwoInts_Request``).
        type: the type's own name, ``String``.
    """

    package: str
    kind: str
    type: str

    def spelled(self, dialect: Dialect) -> str:
        """The canonical spelling in ``dialect`` (``pkg/msg/Type`` or ``pkg/Type``)."""
        if dialect is Dialect.ROS1:
            return f"{self.package}/{self.type}"
        return f"{self.package}/{self.kind}/{self.type}"


def parse_type_name(name: str, kind: Kind = "msg") -> TypeName:
    """Parse a type string of the given kind.

    Args:
        name: ``pkg/Type`` or ``pkg/<kind>/Type``; extra slashes are ignored.
        kind: the kind asked for. A message may also be named
            ``pkg/srv/...`` or ``pkg/action/...`` (a generated part); a service
            or action only by its own kind.

    Returns:
        The parsed name; the kind of a two-part name is ``kind``.

    Raises:
        InvalidTypeNameError: empty, only slashes, one component, more than three,
            a backslash, a middle component that is not an interface kind, or a
            component that is not an identifier (REF §4.6). Primitive names
            such as ``int32`` have one component and are therefore rejected.
    """
    if not isinstance(name, str) or "\\" in name:
        raise InvalidTypeNameError(str(name), kind)
    parts = [p for p in name.split("/") if p]
    middle: str
    if len(parts) == 2:
        package, middle, tail = parts[0], kind, parts[1]
    elif len(parts) == 3:
        package, middle, tail = parts
        allowed = ("msg", "srv", "action") if kind == "msg" else (kind,)
        if middle not in allowed:
            raise InvalidTypeNameError(name, kind)
    else:
        raise InvalidTypeNameError(name, kind)
    if not (_IDENT.match(package) and _IDENT.match(tail)):
        raise InvalidTypeNameError(name, kind)
    return TypeName(package, middle, tail)
