"""Sample payloads and type hashes: what rmw_zenoh puts in a sample, from the graph's types.

rmw_zenoh carries each message as CDR (little endian, with its 4-byte
encapsulation header), the same bytes a ROS 2 bag holds; rosbags writes and
reads them from the graph's own definitions (``TypeRegistry.typestore``), so
a type added with ``--interfaces`` travels like a shipped one.
"""

from __future__ import annotations

from collections import ChainMap
from collections.abc import Iterator, Mapping
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, cast

from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

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
    """The RIHS01 type hash of a service, as rosidl computes it and its keys carry.

    rosidl hashes a service as one type description: a structure named after
    the service (``pkg/srv/Name``) with the fields ``request_message``,
    ``response_message`` and ``event_message``, the event message
    (``pkg/srv/Name_Event``) holding ``service_msgs/msg/ServiceEventInfo info``,
    ``Name_Request[<=1] request`` and ``Name_Response[<=1] response``. rosbags'
    own RIHS01 (``Typestore.hash_rihs01``) hashes that description here, given
    the two made-up structures beside the store's; a ``char`` field counts as
    ``uint8``, as rosidl reads it from a ``.msg`` file (checked against the hash
    rosidl generated for ``std_srvs/srv/SetBool``, tests/zenoh/test_payload.py).

    Raises:
        WireError: ``registry`` is not ROS 2.
        KeyError: the typestore lacks a part of the service.
    """
    _ros2(registry)
    request, response = srvtype.request.rosbags_name, srvtype.response.rosbags_name
    name = request.removesuffix("_Request")
    event = f"{name}_Event"
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
    definitions = _RosidlDefinitions(made_up, registry.typestore().fielddefs)
    # hash_rihs01 reads nothing of its store but ``fielddefs``: a view stands in for it
    view = cast("Typestore", SimpleNamespace(fielddefs=definitions))
    return str(Typestore.hash_rihs01(view, name))


class _RosidlDefinitions(Mapping[str, Any]):
    """rosbags' field definitions with ``made_up`` ones first, ``char`` read as ``uint8``."""

    def __init__(self, made_up: dict[str, Any], store: Mapping[str, Any]) -> None:
        self._defs = ChainMap(made_up, store)  # type: ignore[arg-type]

    def __getitem__(self, name: str) -> Any:
        consts, fields = self._defs[name]
        return consts, [(field, _uint8_chars(desc)) for field, desc in fields]

    def __iter__(self) -> Iterator[str]:
        return iter(self._defs)

    def __len__(self) -> int:
        return len(self._defs)


def _uint8_chars(desc: Any) -> Any:
    kind, rest = desc
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return kind, (_uint8_chars(rest[0]), rest[1])
    if kind == Nodetype.BASE and rest[0] == "char":
        return kind, ("uint8", rest[1])
    return desc
