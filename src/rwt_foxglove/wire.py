"""Payloads in the dialect's wire encoding (CDR, ROS 1), both ways, for messages and services.

A client's message data and service requests come in the wire encoding of the
graph's dialect (``schemas.wire_encoding``); they become the graph's internal
form here, and service responses go back the same way (docs/foxglove.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt_graph.types.registry import codec_for
from rwt_graph.types.wire import CdrError

from .protocol import FoxgloveInputError

if TYPE_CHECKING:
    from collections.abc import Mapping

    from rwt_graph.types import MessageType, TypeRegistry

__all__ = ["decode_wire", "encode_wire"]


def decode_wire(registry: TypeRegistry, mtype: MessageType, data: bytes) -> dict[str, object]:
    """``data``, a message of ``mtype`` in the dialect's wire encoding, in the internal form.

    The encoding is the graph's (``cdr`` for ROS 2, ``ros1``: ``schemas.wire_encoding``),
    read by ``WireCodec.deserialize``.

    Raises:
        FoxgloveInputError: ``data`` is not a message of ``mtype``.
    """
    try:
        return codec_for(registry, mtype).deserialize(data)
    except CdrError as exc:
        raise FoxgloveInputError(exc.message) from None


def encode_wire(registry: TypeRegistry, mtype: MessageType, msg: Mapping[str, object]) -> bytes:
    """``msg`` (the internal form) in the dialect's wire encoding.

    Raises:
        KeyError: the typestore lacks the type (a definition that failed to load).
    """
    return bytes(codec_for(registry, mtype).serialize(msg))
