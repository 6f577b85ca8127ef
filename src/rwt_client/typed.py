"""Typed messages: classes generated from the type registry, or plain dicts.

``message_class("geometry_msgs/msg/Point")`` makes a dataclass with the type's
fields, their defaults (written ``.msg`` defaults included, D7) and its
constants as class attributes. Nested messages stay dicts. ``to_wire`` turns
an instance (or a dict) into the JSON form a server expects.
"""

from __future__ import annotations

import copy
import dataclasses
from functools import cache
from typing import TYPE_CHECKING, Any, Protocol, Self

if TYPE_CHECKING:
    from rwt_graph.types import TypeRegistry

__all__ = ["MessageClass", "message_class", "to_wire"]


class MessageClass(Protocol):
    """What ``message_class`` returns."""

    __msgtype__: str

    @classmethod
    def from_dict(cls, value: object) -> Self:
        """Build an instance from a received message (unknown keys are ignored)."""
        ...


@cache
def _default_registry() -> TypeRegistry:
    # the definitions come from the graph's registry: the ``typed`` extra (rosbags)
    from rwt_graph.types import Dialect, TypeRegistry  # noqa: PLC0415

    return TypeRegistry(Dialect.ROS2)


def message_class(type_name: str, registry: TypeRegistry | None = None) -> type[Any]:
    """Generate a dataclass for a message type.

    Args:
        type_name: ``pkg/msg/Type`` or ``pkg/Type``.
        registry: where to look the type up; a ROS 2 registry by default.

    Raises:
        InvalidTypeNameError, UnknownTypeError: as ``TypeRegistry.message``.
        ModuleNotFoundError: the ``typed`` extra (``pip install "rwt-rosbridge[typed]"``) is
            not installed.
    """
    registry = registry or _default_registry()
    msgtype = registry.message(type_name)
    defaults = msgtype.default()
    fields = [
        (f.name, Any, dataclasses.field(default_factory=_copier(defaults[f.name])))
        for f in msgtype.fields
    ]
    namespace: dict[str, object] = {c.name: c.value for c in msgtype.constants}
    namespace["__msgtype__"] = msgtype.name
    namespace["from_dict"] = classmethod(_from_dict)
    return dataclasses.make_dataclass(msgtype.name.rsplit("/", 1)[-1], fields, namespace=namespace)


def _copier(value: object) -> Any:
    return lambda: copy.deepcopy(value)


def _from_dict(cls: type[Any], value: object) -> Any:
    names = {f.name for f in dataclasses.fields(cls)}
    items = value.items() if isinstance(value, dict) else ()
    return cls(**{k: v for k, v in items if k in names})


def to_wire(msg: object) -> object:
    """A message as JSON-ready data: dataclass instances become dicts, the rest is unchanged."""
    if dataclasses.is_dataclass(msg) and not isinstance(msg, type):
        return dataclasses.asdict(msg)
    return msg
