"""Sample payloads and type hashes: what rmw_zenoh puts in a sample, from the graph's types.

rmw_zenoh carries each message as CDR (little endian, with its 4-byte
encapsulation header), the same bytes a ROS 2 bag holds; rosbags writes and
reads them from the graph's own definitions (``TypeRegistry.typestore``), so
a type added with ``--interfaces`` travels like a shipped one.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt_graph.types import Dialect

from .wire import WireError

if TYPE_CHECKING:
    from rwt_graph.types import MessageType, ServiceType, TypeRegistry

__all__ = [
    "decode_message",
    "decode_sample",
    "encode_message",
    "encode_sample",
    "service_hash",
    "type_hash",
]


def _ros2(registry: TypeRegistry) -> None:
    if registry.dialect is not Dialect.ROS2:
        raise WireError("rmw_zenoh speaks ROS 2 types: use a ROS 2 registry")


def type_hash(registry: TypeRegistry, type_name: str) -> str:
    """The RIHS01 hash of a message type, as keys and tokens carry it.

    Raises:
        WireError: ``registry`` is not ROS 2.
        UnknownTypeError, InvalidTypeNameError: the type is not known.
    """
    _ros2(registry)
    mtype = registry.message(type_name)
    return str(registry.typestore().hash_rihs01(mtype.rosbags_name))


def encode_sample(registry: TypeRegistry, type_name: str, msg: dict[str, object]) -> bytes:
    """Serialize a message in the internal form to CDR, as a sample's payload.

    Raises:
        WireError: ``registry`` is not ROS 2.
        UnknownTypeError, InvalidTypeNameError: the type is not known.
    """
    _ros2(registry)
    mtype = registry.message(type_name)
    return bytes(registry.codec(mtype).serialize(msg))


def decode_sample(registry: TypeRegistry, type_name: str, data: bytes) -> dict[str, object]:
    """Read a sample's CDR payload into the internal form.

    Raises:
        WireError: ``registry`` is not ROS 2, or ``data`` is not a valid CDR message
            of the type (a peer's bytes: never anything else).
        UnknownTypeError, InvalidTypeNameError: the type is not known.
    """
    _ros2(registry)
    mtype = registry.message(type_name)
    try:
        obj = registry.typestore().deserialize_cdr(data, mtype.rosbags_name)
    except Exception as exc:  # rosbags raises assorted errors for malformed bytes
        raise WireError(f"{type_name}: not a CDR message of this type ({exc})") from None
    return mtype.from_python(obj)


def encode_message(
    registry: TypeRegistry, mtype: MessageType, msg: dict[str, object]
) -> bytes | bytearray:
    """Serialize a message of any part type (a service's request or response) to CDR.

    Returns:
        The CDR bytes; a large message's come as rosbags' own fresh buffer (a
        ``bytearray`` nobody else holds), which Zenoh takes as it takes ``bytes``:
        copying 1 MB into ``bytes`` first cost as much as serializing it.

    Raises:
        WireError: ``registry`` is not ROS 2.
    """
    _ros2(registry)
    raw = registry.codec(mtype).serialize(msg)
    owner = raw.obj if isinstance(raw, memoryview) else None
    if isinstance(owner, bytearray) and len(owner) == raw.nbytes:  # type: ignore[union-attr]
        return owner
    return bytes(raw)


def decode_message(registry: TypeRegistry, mtype: MessageType, data: bytes) -> dict[str, object]:
    """Read the CDR of a message of any part type into the internal form.

    Raises:
        WireError: ``registry`` is not ROS 2, or ``data`` is not a CDR message of the type.
    """
    _ros2(registry)
    try:
        obj = registry.typestore().deserialize_cdr(data, mtype.rosbags_name)
    except Exception as exc:  # rosbags raises assorted errors for malformed bytes
        raise WireError(f"{mtype.name}: not a CDR message of this type ({exc})") from None
    return mtype.from_python(obj)


def service_hash(registry: TypeRegistry, srvtype: ServiceType) -> str:
    """The type hash a service's key and token carry: RIHS01 of its request type.

    rosidl hashes a service as one description of its request, response and
    event messages; rwt does not compute that yet, so callers match a service's
    key with a wildcard in place of the hash (docs/zenoh.md).

    Raises:
        WireError: ``registry`` is not ROS 2.
    """
    _ros2(registry)
    return str(registry.typestore().hash_rihs01(srvtype.request.rosbags_name))
