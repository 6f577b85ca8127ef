"""Message, service and action types: the registry and what it resolves (docs/embedding.md).

Also the policies of a topic's QoS (``History``, ``Reliability``, ``Durability``)
that ``rwt.QosProfile`` takes (protocol 2.1.0).

``rwt.Graph`` takes a ``TypeRegistry`` (``graph.registry``); it reads interface
files and the rosbags stores of a dialect (ROS 2 or ROS 1, D6) and resolves a
type string to a ``MessageType``, ``ServiceType`` or ``ActionType``.

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_graph.types import (
        ActionType,
        ArrayKind,
        Constant,
        Converted,
        DefinitionError,
        Dialect,
        FieldSpec,
        FieldType,
        InvalidTypeNameError,
        MessageType,
        ServiceType,
        TypeRegistry,
        UnknownTypeError,
    )
    from rwt_graph.types.wire import CdrError
    from rwt_protocol.qos import Durability, History, Reliability

__all__ = [
    "ActionType",
    "ArrayKind",
    "CdrError",
    "Constant",
    "Converted",
    "DefinitionError",
    "Dialect",
    "Durability",
    "FieldSpec",
    "FieldType",
    "History",
    "InvalidTypeNameError",
    "MessageType",
    "Reliability",
    "ServiceType",
    "TypeRegistry",
    "UnknownTypeError",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
