"""Payloads in the dialect's wire encoding (CDR, ROS 1), both ways, for messages and services.

A client's message data and service requests come in the wire encoding of the
graph's dialect (``schemas.wire_encoding``); they become the graph's internal
form here, and service responses go back the same way (docs/foxglove.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt_graph.types.registry import codec_for
from rwt_graph.types.wire import CdrError, read_cdr, wire_input
from rwt_protocol.errors import RwtError

from .protocol import FoxgloveInputError

if TYPE_CHECKING:
    from collections.abc import Mapping

    from rwt_graph.types import MessageType, TypeRegistry

__all__ = ["decode_wire", "encode_wire"]


def decode_wire(
    registry: TypeRegistry, wire: str, mtype: MessageType, data: bytes
) -> dict[str, object]:
    """``data``, a message of ``mtype`` in ``wire`` (``cdr`` or ``ros1``), in the internal form.

    Raises:
        FoxgloveInputError: ``data`` is not a message of ``mtype``.
    """
    store = registry.typestore()
    try:
        if wire == "cdr":
            obj = read_cdr(store, wire_input(data), mtype.rosbags_name)
        else:
            obj = store.deserialize_ros1(data, mtype.rosbags_name)
        return mtype.from_python(obj)
    except (CdrError, RwtError, KeyError, ValueError, TypeError, IndexError) as exc:
        text = exc.message if isinstance(exc, RwtError) else str(exc)
        raise FoxgloveInputError(
            f"{mtype.name}: not a {wire} message of this type ({text[:200]})"
        ) from None


def encode_wire(registry: TypeRegistry, mtype: MessageType, msg: Mapping[str, object]) -> bytes:
    """``msg`` (the internal form) in the dialect's wire encoding.

    Raises:
        KeyError: the typestore lacks the type (a definition that failed to load).
    """
    return bytes(codec_for(registry, mtype).serialize(msg))
