"""Sample payloads and type hashes: what rmw_zenoh puts in a sample, from the graph's types.

rmw_zenoh carries each message as CDR (little endian, with its 4-byte
encapsulation header), the same bytes a ROS 2 bag holds; rosbags writes and
reads them from the graph's own definitions (``TypeRegistry.typestore``), so
a type added with ``--interfaces`` travels like a shipped one.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Nodetype

from rwt_graph.types import Dialect, codec_for
from rwt_graph.types.hashes import rihs01
from rwt_graph.types.wire import CdrError

from .wire import WireError

if TYPE_CHECKING:
    from rwt_graph.types import MessageType, ServiceType, TypeRegistry

__all__ = [
    "decode_message",
    "decode_sample",
    "encode_message",
    "encode_sample",
    "message_hash",
    "named_service_hash",
    "owned_cdr",
    "prepare_codecs",
    "service_hash",
    "type_hash",
]


def _ros2(registry: TypeRegistry) -> None:
    if registry.dialect is not Dialect.ROS2:
        raise WireError("rmw_zenoh speaks ROS 2 types: use a ROS 2 registry")


def prepare_codecs(registry: TypeRegistry) -> None:
    """Load what every sample's CDR needs, once, before the first sample (blocking).

    That is the registry's type store (rosbags builds it in about 0.2 s of CPU)
    and numpy, which rosbags' messages hold and rwt's converters import on their
    first use (about 0.1 s more). Left to the first sample, the import stopped
    the event loop once in every process of ``--workers``, inside the first
    second of traffic (benchmarks/JOURNAL.md, "Workers' CPU per delivery"). A
    type's own converters are still compiled on its first sample (a few ms).
    """
    registry.typestore()
    import numpy  # noqa: F401, PLC0415 - what the converters import on first use


def type_hash(registry: TypeRegistry, type_name: str) -> str:
    """The RIHS01 hash of a message type, as rosidl computes it and keys and tokens carry.

    A ``char`` field counts as ``uint8``, as rosidl reads it from a ``.msg``
    file (checked against rosidl's generated hash of ``std_msgs/msg/Char``,
    tests/zenoh/test_payload.py); rosbags alone would hash it as ``char``.

    Raises:
        WireError: ``registry`` is not ROS 2.
        UnknownTypeError, InvalidTypeNameError: the type is not known.
    """
    _ros2(registry)
    return message_hash(registry, registry.message(type_name).rosbags_name)


def encode_sample(registry: TypeRegistry, type_name: str, msg: dict[str, object]) -> bytes:
    """Serialize a message in the internal form to CDR, as a sample's payload.

    Raises:
        WireError: ``registry`` is not ROS 2.
        UnknownTypeError, InvalidTypeNameError: the type is not known.
    """
    _ros2(registry)
    mtype = registry.message(type_name)
    return registry.serialize(mtype, msg)


def decode_sample(registry: TypeRegistry, type_name: str, data: bytes) -> dict[str, object]:
    """Read a sample's CDR payload into the internal form.

    Raises:
        WireError: ``registry`` is not ROS 2, or ``data`` is not a valid CDR message
            of the type (a peer's bytes: never anything else).
        UnknownTypeError, InvalidTypeNameError: the type is not known.
    """
    _ros2(registry)
    return decode_message(registry, registry.message(type_name), data)


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
    return owned_cdr(codec_for(registry, mtype).serialize(msg))


def owned_cdr(raw: bytes | memoryview) -> bytes | bytearray:
    """Serialized CDR as Zenoh takes it: rosbags' fresh buffer under a view, else ``bytes``.

    rosbags returns a read-only view of a ``bytearray`` nobody else holds; that
    buffer is handed over as it is (copying 1 MB into ``bytes`` cost as much as
    serializing it).
    """
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
        return codec_for(registry, mtype).deserialize(data)
    except CdrError as exc:
        raise WireError(exc.message) from None


def service_hash(registry: TypeRegistry, srvtype: ServiceType) -> str:
    """The RIHS01 type hash of a service, as rosidl computes it and its keys carry.

    See ``named_service_hash``, which this applies to the service's name (checked
    against the hash rosidl generated for ``std_srvs/srv/SetBool`` and the one
    rmw_zenoh's design document shows for ``example_interfaces/srv/AddTwoInts``,
    tests/zenoh/test_payload.py).

    Raises:
        WireError: ``registry`` is not ROS 2.
        KeyError: the typestore lacks a part of the service.
    """
    return named_service_hash(registry, srvtype.request.rosbags_name.removesuffix("_Request"))


def named_service_hash(registry: TypeRegistry, name: str) -> str:
    """The RIHS01 hash of the service ``name``, its parts in the registry's type store.

    ``name`` is ``pkg/srv/Name``, or an action's ``pkg/action/Name_SendGoal`` or
    ``pkg/action/Name_GetResult``; the parts are ``<name>_Request`` and
    ``<name>_Response``.

    rosidl hashes a service as one type description: a structure named after
    the service with the fields ``request_message``, ``response_message`` and
    ``event_message``, the event message (``<name>_Event``) holding
    ``service_msgs/msg/ServiceEventInfo info``, ``<name>_Request[<=1] request``
    and ``<name>_Response[<=1] response``; an action's two services are hashed
    the same way. rosbags' own RIHS01 (``Typestore.hash_rihs01``) hashes that
    description here, given the two made-up structures beside the store's; a
    ``char`` field counts as ``uint8``, as in ``type_hash``.

    Raises:
        WireError: ``registry`` is not ROS 2.
        KeyError: the typestore lacks a part of the service.
    """
    _ros2(registry)
    request, response, event = f"{name}_Request", f"{name}_Response", f"{name}_Event"
    made_up: dict[str, Any] = {
        name: (
            [],
            [
                ("request_message", (Nodetype.NAME, request)),
                ("response_message", (Nodetype.NAME, response)),
                ("event_message", (Nodetype.NAME, event)),
            ],
        ),
        event: (
            [],
            [
                ("info", (Nodetype.NAME, "service_msgs/msg/ServiceEventInfo")),
                ("request", (Nodetype.SEQUENCE, ((Nodetype.NAME, request), 1))),
                ("response", (Nodetype.SEQUENCE, ((Nodetype.NAME, response), 1))),
            ],
        ),
    }
    return _rihs01(registry, name, made_up)


def message_hash(registry: TypeRegistry, name: str) -> str:
    """The RIHS01 hash of a structure in the registry's type store, as ``type_hash`` computes it.

    ``name`` is rosbags' name of it, such as an action's ``pkg/action/Name_FeedbackMessage``.

    Raises:
        WireError: ``registry`` is not ROS 2.
        KeyError: the typestore lacks the structure.
    """
    _ros2(registry)
    return _rihs01(registry, name, {})


def _rihs01(registry: TypeRegistry, name: str, made_up: dict[str, Any]) -> str:
    """The RIHS01 of ``name`` over the store plus ``made_up`` (``rwt_graph.types.hashes``)."""
    return rihs01(registry, name, made_up)
