"""ROS 2 messages as CDR bytes, read and written by rwt's codec (rosbags), not by rclpy.

The link carries topics as serialized CDR (``raw=True`` subscriptions, bytes
published as they are), so no field goes through rclpy's message objects;
service requests and responses, which rclpy only hands over as objects, cross
through ``rclpy.serialization`` into the same bytes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt_graph.types.registry import codec_for
from rwt_graph.types.wire import CdrError
from rwt_protocol.errors import GraphError

if TYPE_CHECKING:
    from rwt_graph.types import MessageType, TypeRegistry

__all__ = ["decode", "encode"]


def decode(registry: TypeRegistry, mtype: MessageType, data: bytes) -> dict[str, object]:
    """The message in the internal form from its CDR (trailing bytes allowed).

    Raises:
        GraphError: ``data`` is not a CDR message of ``mtype`` (a peer's bytes).
    """
    try:
        return codec_for(registry, mtype).deserialize(data)
    except CdrError as exc:
        raise GraphError(exc.message) from None


def encode(registry: TypeRegistry, mtype: MessageType, msg: dict[str, object]) -> bytes:
    """The CDR of a message in the internal form.

    Raises:
        KeyError: the typestore lacks the type.
    """
    return registry.serialize(mtype, msg)
