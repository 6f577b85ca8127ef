"""Channel encodings and schemas of the graph's message types, as Foxglove reads them.

A ROS 2 graph sends ``cdr`` with schema encoding ``ros2msg``, as foxglove_bridge
does: the ``.msg`` text of the type, then each dependency after a line of 80
``=`` and a line ``MSG: pkg/Type`` (``MessageType.full_text``); the payload is
the CDR serialization with its 4-byte encapsulation header. A ROS 1 graph sends
``ros1`` with ``ros1msg`` (genmsg's full text) and the ROS 1 serialization.
Clients may publish in the dialect's encoding or in ``json`` (docs/foxglove.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from rwt_graph.types import Dialect

if TYPE_CHECKING:
    from rwt_graph.types import MessageType

__all__ = ["JSON", "Schema", "metadata_for", "schema_of", "supported_encodings"]

JSON: Final = "json"

_WIRE: Final = {Dialect.ROS2: ("cdr", "ros2msg"), Dialect.ROS1: ("ros1", "ros1msg")}
_DISTRO: Final = {Dialect.ROS2: "kilted", Dialect.ROS1: "noetic"}
"""``ROS_DISTRO`` in ``serverInfo``'s metadata: clients pick ROS 1 or ROS 2 parsing by it."""


@dataclass(frozen=True, slots=True)
class Schema:
    """How a channel of one message type is described and encoded.

    Attributes:
        encoding: the payload encoding (``cdr`` or ``ros1``).
        schema_name: the type's name (``std_msgs/msg/String``; ROS 1 ``std_msgs/String``).
        schema: the definition text with its dependencies.
        schema_encoding: ``ros2msg`` or ``ros1msg``.
    """

    encoding: str
    schema_name: str
    schema: str
    schema_encoding: str


def schema_of(mtype: MessageType) -> Schema:
    """The channel description of ``mtype`` in its dialect."""
    encoding, schema_encoding = _WIRE[mtype.dialect]
    return Schema(encoding, mtype.name, mtype.full_text(), schema_encoding)


def supported_encodings(dialect: Dialect) -> list[str]:
    """What clients may publish in: the dialect's wire encoding and ``json``."""
    return [_WIRE[dialect][0], JSON]


def wire_encoding(dialect: Dialect) -> str:
    """The dialect's wire encoding name (``cdr`` or ``ros1``)."""
    return _WIRE[dialect][0]


def metadata_for(dialect: Dialect) -> dict[str, str]:
    """``serverInfo``'s metadata: the ROS distribution the types follow."""
    return {"ROS_DISTRO": _DISTRO[dialect]}
