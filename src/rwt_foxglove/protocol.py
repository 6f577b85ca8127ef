"""The Foxglove WebSocket protocol's ops as typed models, parsed and encoded without I/O.

Facts from the Foxglove SDK's server (``rust/foxglove/src/protocol/v1``) and the
``@foxglove/ws-protocol`` client's types (docs/foxglove.md): JSON text ops carry
an ``op`` field; binary frames start with a one-byte opcode and are little-endian.
Server to client: ``serverInfo``, ``status``, ``removeStatus``, ``advertise``,
``unadvertise``, ``advertiseServices``, ``unadvertiseServices``,
``serviceCallFailure``, ``parameterValues``, ``connectionGraphUpdate`` (text),
message data (``0x01``: u32 subscription id, u64 log time in ns, payload), time
(``0x02``: u64 ns), service call response (``0x03``: u32 service id, u32 call
id, u32 encoding length, encoding, payload), fetch asset response (``0x04``:
u32 request id, u8 status, u32 error length, error text, data) and playback
state (``0x05``: u8 status, u64 time in ns, f32 speed, u8 did seek, u32 request
id length, request id). Client to
server: ``subscribe``, ``unsubscribe``, ``advertise``, ``unadvertise``,
``getParameters``, ``setParameters``, ``subscribeParameterUpdates``,
``unsubscribeParameterUpdates``, ``subscribeConnectionGraph``,
``unsubscribeConnectionGraph``, ``fetchAsset`` (text), client message data
(``0x01``: u32 client channel id, payload), service call request (``0x02``:
as the response) and playback control request (``0x03``: u8 command, f32
speed, u8 had seek, u64 seek time in ns, u32 request id length, request id).

Every bad input becomes a ``FoxgloveInputError`` whose text goes to the peer as
an error ``status``; the connection goes on (docs/foxglove.md, limits). JSON
text is decoded under the rules of rosbridge frames (``decode_json_text``: at
most 100 levels, no lone surrogate, integers within 64 bits).
"""

from __future__ import annotations

import functools
import math
import struct
from enum import IntEnum
from typing import TYPE_CHECKING, Annotated, Any, Final

import msgspec

from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.errors import RemoteProtocolError

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

__all__ = [
    "CLIENT_OPS",
    "MAX_LIST_ENTRIES",
    "SUBPROTOCOLS",
    "UNSUPPORTED_OPS",
    "Advertise",
    "AdvertiseServices",
    "AdvertisedService",
    "Channel",
    "ClientAdvertise",
    "ClientChannel",
    "ClientMessageData",
    "ClientOp",
    "ClientUnadvertise",
    "ConnectionGraphUpdate",
    "FetchAsset",
    "FetchAssetStatus",
    "FoxgloveInputError",
    "GetParameters",
    "ParameterIn",
    "ParameterOut",
    "ParameterValues",
    "PlaybackCommand",
    "PlaybackControlRequest",
    "PlaybackStatusCode",
    "PublishedTopic",
    "RemoveStatus",
    "ServerInfo",
    "Service",
    "ServiceCallFailure",
    "ServiceCallRequest",
    "ServiceSchema",
    "SetParameters",
    "Status",
    "StatusLevel",
    "Subscribe",
    "SubscribeConnectionGraph",
    "SubscribeParameterUpdates",
    "SubscribedTopic",
    "Subscription",
    "Timestamp",
    "Unadvertise",
    "UnadvertiseServices",
    "Unsubscribe",
    "UnsubscribeConnectionGraph",
    "UnsubscribeParameterUpdates",
    "encode_fetch_asset_response",
    "encode_message_data",
    "encode_message_header",
    "encode_op",
    "encode_playback_state",
    "encode_service_call_response",
    "encode_time",
    "parse_binary",
    "parse_text",
    "select_subprotocol",
]

SUBPROTOCOLS: Final = ("foxglove.sdk.v1", "foxglove.websocket.v1")
"""The WebSocket subprotocols answered: the SDK's name and the older clients' one."""

U32_MAX: Final = 2**32 - 1
MAX_LIST_ENTRIES: Final = 10_000
"""Entries one list op may carry (``subscribe``'s subscriptions, ``unsubscribe``'s ids,
``advertise``'s channels, parameter names...): a longer list is refused whole with one
error status before any entry is handled, so one frame costs a bounded amount of work
(docs/limits.md). As many as the channels a client may be advertised."""

_Bounded = msgspec.Meta(max_length=MAX_LIST_ENTRIES)
_MESSAGE_DATA: Final = 0x01
_TIME: Final = 0x02
_FETCH_ASSET_RESPONSE: Final = 0x04
_SERVICE_CALL_REQUEST: Final = 0x02
_SERVICE_CALL_RESPONSE: Final = 0x03
_PLAYBACK_CONTROL_REQUEST: Final = 0x03
_PLAYBACK_STATE: Final = 0x05
_PLAYBACK_REQUEST = struct.Struct("<BfBQI")  # command, speed, had seek, seek time, id length
_PLAYBACK_STATE_HEADER = struct.Struct("<BBQfBI")  # opcode, status, time, speed, did seek, id len
_DATA_HEADER = struct.Struct("<BIQ")  # opcode, subscription id, log time (ns)
_CLIENT_DATA_HEADER = struct.Struct("<BI")  # opcode, client channel id
_TIME_FRAME = struct.Struct("<BQ")
_CALL_HEADER = struct.Struct("<III")  # service id, call id, encoding length (after the opcode)
_ASSET_HEADER = struct.Struct("<BIBI")  # opcode, request id, status, error length


def select_subprotocol(offered: Iterable[str]) -> str | None:
    """The first Foxglove subprotocol the client offers, in its order, or None."""
    return next((name for name in offered if name in SUBPROTOCOLS), None)


class FoxgloveInputError(RemoteProtocolError):
    """The client sent something this server cannot use; it becomes an error ``status``."""


class StatusLevel(IntEnum):
    """A ``status`` op's level."""

    INFO = 0
    WARNING = 1
    ERROR = 2


def _u32(value: int, what: str) -> int:
    if not 0 <= value <= U32_MAX:
        raise FoxgloveInputError(f"{what} {value} is not a 32-bit unsigned integer")
    return value


# ---- client ops (text) --------------------------------------------------------------


class Subscription(msgspec.Struct, frozen=True):
    """One entry of ``subscribe``: the client's subscription id and a server channel id."""

    id: int
    channelId: int


class Subscribe(msgspec.Struct, frozen=True):
    """``subscribe``: start message data of channels under the client's ids."""

    subscriptions: Annotated[list[Subscription], _Bounded]


class Unsubscribe(msgspec.Struct, frozen=True):
    """``unsubscribe``: stop the subscriptions with these ids."""

    subscriptionIds: Annotated[list[int], _Bounded]


class ClientChannel(msgspec.Struct, frozen=True):
    """A channel the client will publish on (``advertise`` from the client)."""

    id: int
    topic: str
    encoding: str
    schemaName: str
    schema: str | None = None
    schemaEncoding: str | None = None


class ClientAdvertise(msgspec.Struct, frozen=True):
    """``advertise`` from the client: channels it will publish on."""

    channels: Annotated[list[ClientChannel], _Bounded]


class ClientUnadvertise(msgspec.Struct, frozen=True):
    """``unadvertise`` from the client: channels it stops publishing on."""

    channelIds: Annotated[list[int], _Bounded]


class ClientMessageData(msgspec.Struct, frozen=True):
    """Binary client message data (opcode 0x01): one message on a client channel."""

    channel_id: int
    payload: bytes | memoryview


class ServiceCallRequest(msgspec.Struct, frozen=True):
    """Binary service call request (opcode 0x02): a call of a server service by the client's id."""

    service_id: int
    call_id: int
    encoding: str
    payload: bytes | memoryview


class GetParameters(msgspec.Struct, frozen=True):
    """``getParameters``: the values of these parameters (none named: all); ``id`` is echoed."""

    parameterNames: Annotated[list[str], _Bounded]
    id: str | None = None


class ParameterIn(msgspec.Struct, frozen=True):
    """One parameter of ``setParameters``: no ``value`` (or null) deletes it.

    ``type`` is ``float64``, ``float64_array`` or ``byte_array`` when JSON alone
    cannot tell (a float written without a fraction; bytes as base64 text).
    """

    name: str
    value: Any = None
    type: str | None = None


class SetParameters(msgspec.Struct, frozen=True):
    """``setParameters``: set or delete parameters; with ``id``, ``parameterValues`` answers."""

    parameters: Annotated[list[ParameterIn], _Bounded]
    id: str | None = None


class SubscribeParameterUpdates(msgspec.Struct, frozen=True):
    """``subscribeParameterUpdates``: push changes of these parameters."""

    parameterNames: Annotated[list[str], _Bounded]


class UnsubscribeParameterUpdates(msgspec.Struct, frozen=True):
    """``unsubscribeParameterUpdates``: stop pushing changes of these parameters."""

    parameterNames: Annotated[list[str], _Bounded]


class FetchAsset(msgspec.Struct, frozen=True):
    """``fetchAsset``: the client asks for the file at ``uri``; answered under ``requestId``."""

    uri: str
    requestId: int


class PlaybackCommand(IntEnum):
    """What a playback control request asks for after its seek and speed."""

    PLAY = 0
    PAUSE = 1


class PlaybackControlRequest(msgspec.Struct, frozen=True):
    """A playback control request (binary ``0x03``): the client's playback bar.

    ``seek_ns`` is the absolute time to go to (ns since the epoch), None without a seek.
    """

    command: PlaybackCommand
    speed: float
    seek_ns: int | None
    request_id: str


class PlaybackStatusCode(IntEnum):
    """A playback state's status byte."""

    PLAYING = 0
    PAUSED = 1
    BUFFERING = 2
    ENDED = 3


class SubscribeConnectionGraph(msgspec.Struct, frozen=True):
    """``subscribeConnectionGraph``: send the graph, then its changes."""


class UnsubscribeConnectionGraph(msgspec.Struct, frozen=True):
    """``unsubscribeConnectionGraph``: stop sending the graph's changes."""


ClientOp = (
    Subscribe
    | Unsubscribe
    | ClientAdvertise
    | ClientUnadvertise
    | FetchAsset
    | ClientMessageData
    | ServiceCallRequest
)

TextOp = (
    Subscribe
    | Unsubscribe
    | ClientAdvertise
    | ClientUnadvertise
    | GetParameters
    | SetParameters
    | SubscribeParameterUpdates
    | UnsubscribeParameterUpdates
    | SubscribeConnectionGraph
    | UnsubscribeConnectionGraph
    | FetchAsset
)

CLIENT_OPS: Final[dict[str, type[TextOp]]] = {
    "subscribe": Subscribe,
    "unsubscribe": Unsubscribe,
    "advertise": ClientAdvertise,
    "unadvertise": ClientUnadvertise,
    "getParameters": GetParameters,
    "setParameters": SetParameters,
    "subscribeParameterUpdates": SubscribeParameterUpdates,
    "unsubscribeParameterUpdates": UnsubscribeParameterUpdates,
    "subscribeConnectionGraph": SubscribeConnectionGraph,
    "unsubscribeConnectionGraph": UnsubscribeConnectionGraph,
    "fetchAsset": FetchAsset,
}
"""The text ops this server handles, by ``op``."""

UNSUPPORTED_OPS: Final[frozenset[str]] = frozenset()
"""Ops of capabilities this server does not announce (docs/foxglove.md, not done yet)."""


def parse_text(data: bytes | str) -> TextOp:
    """Parse one JSON text frame of the client.

    Raises:
        FoxgloveInputError: not JSON, not an object, no ``op``, an op not
            handled, a field missing or of the wrong type, an id that is no u32.
    """
    try:
        value = decode_json_text(data, "frame")
    except RemoteProtocolError as exc:
        raise FoxgloveInputError(exc.message) from None
    if not isinstance(value, dict):
        raise FoxgloveInputError("frame: expected a JSON object")
    op = value.get("op")
    if not isinstance(op, str):
        raise FoxgloveInputError("frame: no op (expected a string at $.op)")
    model = CLIENT_OPS.get(op)
    if model is None:
        if op in UNSUPPORTED_OPS:
            raise FoxgloveInputError(f"op {op[:40]!r} is not supported by this server")
        raise FoxgloveInputError(f"unknown op {op[:40]!r}")
    try:
        parsed = msgspec.convert(value, model)
    except msgspec.ValidationError as exc:
        raise FoxgloveInputError(f"{op}: {exc}") from None
    _check_ids(parsed)
    return parsed


def _check_ids(op: TextOp) -> None:
    if isinstance(op, Subscribe):
        for each in op.subscriptions:
            _u32(each.id, "subscription id")
            _u32(each.channelId, "channel id")
    elif isinstance(op, Unsubscribe):
        for sid in op.subscriptionIds:
            _u32(sid, "subscription id")
    elif isinstance(op, ClientAdvertise):
        for channel in op.channels:
            _u32(channel.id, "client channel id")
    elif isinstance(op, FetchAsset):
        _u32(op.requestId, "request id")
    elif isinstance(op, ClientUnadvertise):
        for cid in op.channelIds:
            _u32(cid, "client channel id")


def parse_binary(data: bytes) -> ClientMessageData | ServiceCallRequest | PlaybackControlRequest:
    """Parse one binary frame of the client.

    The payload is a view of ``data`` (no copy of a large message).

    Raises:
        FoxgloveInputError: an empty frame, an opcode not handled, a frame
            shorter than its header, an encoding name that is not UTF-8, a bad
            playback control request (``_playback_control_request``).
    """
    if not data:
        raise FoxgloveInputError("empty binary frame")
    opcode = data[0]
    if opcode == _MESSAGE_DATA:
        if len(data) < _CLIENT_DATA_HEADER.size:
            raise FoxgloveInputError(
                f"client message data of {len(data)} bytes: shorter than its "
                f"{_CLIENT_DATA_HEADER.size}-byte header"
            )
        _, channel_id = _CLIENT_DATA_HEADER.unpack_from(data)
        return ClientMessageData(channel_id, memoryview(data)[_CLIENT_DATA_HEADER.size :])
    if opcode == _SERVICE_CALL_REQUEST:
        return _service_call_request(data)
    if opcode == _PLAYBACK_CONTROL_REQUEST:
        return _playback_control_request(data)
    raise FoxgloveInputError(f"unknown binary opcode 0x{opcode:02x}")


def _service_call_request(data: bytes) -> ServiceCallRequest:
    header = 1 + _CALL_HEADER.size
    if len(data) < header:
        raise FoxgloveInputError(
            f"service call request of {len(data)} bytes: shorter than its {header}-byte header"
        )
    service_id, call_id, length = _CALL_HEADER.unpack_from(data, 1)
    if len(data) - header < length:
        raise FoxgloveInputError(
            f"service call request: encoding of {length} bytes past the frame's end"
        )
    try:
        encoding = bytes(data[header : header + length]).decode("utf-8")
    except UnicodeDecodeError:
        raise FoxgloveInputError("service call request: the encoding is not UTF-8") from None
    return ServiceCallRequest(service_id, call_id, encoding, memoryview(data)[header + length :])


def _playback_control_request(data: bytes) -> PlaybackControlRequest:
    """Parse a playback control request, stricter than the SDK's server.

    Raises:
        FoxgloveInputError: shorter than its 19-byte header or than its request
            id, longer than both (the SDK ignores trailing bytes; rwt refuses
            them), a command other than play (0) or pause (1), a speed that is
            not a finite number above 0, a request id that is not UTF-8 (its
            length is bounded by the session: ``limits.MAX_PLAYBACK_REQUEST_ID_BYTES``).
    """
    what = "playback control request"
    header = 1 + _PLAYBACK_REQUEST.size
    if len(data) < header:
        raise FoxgloveInputError(
            f"{what} of {len(data)} bytes: shorter than its {header}-byte header"
        )
    command, speed, had_seek, seek_ns, length = _PLAYBACK_REQUEST.unpack_from(data, 1)
    if len(data) != header + length:
        raise FoxgloveInputError(
            f"{what} of {len(data)} bytes: its {length}-byte request id needs {header + length}"
        )
    if command not in (PlaybackCommand.PLAY, PlaybackCommand.PAUSE):
        raise FoxgloveInputError(f"{what}: unknown command {command} (0 play, 1 pause)")
    if not (math.isfinite(speed) and speed > 0):
        raise FoxgloveInputError(f"{what}: speed {speed} is not a finite number above 0")
    try:
        request_id = bytes(data[header:]).decode("utf-8")
    except UnicodeDecodeError:
        raise FoxgloveInputError(f"{what}: the request id is not UTF-8") from None
    return PlaybackControlRequest(
        PlaybackCommand(command), speed, seek_ns if had_seek else None, request_id
    )


# ---- server ops -------------------------------------------------------------------


class Timestamp(msgspec.Struct, frozen=True):
    """A time in ``serverInfo``: whole seconds and nanoseconds since the epoch (each u32)."""

    sec: int
    nsec: int

    @classmethod
    def of(cls, time_ns: int) -> Timestamp:
        """``time_ns`` (ns since the epoch) split; seconds clamped to u32 as the SDK does."""
        sec, nsec = divmod(max(0, time_ns), 1_000_000_000)
        return cls(min(sec, 0xFFFF_FFFF), nsec)


class ServerInfo(msgspec.Struct, frozen=True, tag_field="op", tag="serverInfo", omit_defaults=True):
    """``serverInfo``: sent first on every connection.

    ``dataStartTime`` and ``dataEndTime`` (the range a playback bar seeks in) come
    with the ``playbackControl`` capability only.
    """

    name: str
    capabilities: list[str]
    supportedEncodings: list[str]
    metadata: dict[str, str]
    sessionId: str
    dataStartTime: Timestamp | None = None
    dataEndTime: Timestamp | None = None


class Status(msgspec.Struct, frozen=True, tag_field="op", tag="status", omit_defaults=True):
    """``status``: a message for the user (level 0 info, 1 warning, 2 error)."""

    level: int
    message: str
    id: str | None = None


class RemoveStatus(msgspec.Struct, frozen=True, tag_field="op", tag="removeStatus"):
    """``removeStatus``: withdraw statuses sent with these ids."""

    statusIds: list[str]


class Channel(msgspec.Struct, frozen=True):
    """A server channel: one topic with its encoding and schema."""

    id: int
    topic: str
    encoding: str
    schemaName: str
    schema: str
    schemaEncoding: str


class Advertise(msgspec.Struct, frozen=True, tag_field="op", tag="advertise"):
    """``advertise``: channels the client may subscribe to."""

    channels: list[Channel]


class Unadvertise(msgspec.Struct, frozen=True, tag_field="op", tag="unadvertise"):
    """``unadvertise``: channels gone (their subscriptions end)."""

    channelIds: list[int]


class ServiceSchema(msgspec.Struct, frozen=True):
    """A service's request or response: how it is encoded and its schema (as a channel's)."""

    encoding: str
    schemaName: str
    schemaEncoding: str
    schema: str


class Service(msgspec.Struct, frozen=True):
    """A server service, its request and response described as channels are.

    The deprecated ``requestSchema``/``responseSchema`` are not sent (as the
    Foxglove SDK's server: Lichtblick warns once per service that has them).
    """

    id: int
    name: str
    type: str
    request: ServiceSchema
    response: ServiceSchema


class AdvertiseServices(msgspec.Struct, frozen=True, tag_field="op", tag="advertiseServices"):
    """``advertiseServices``: services the client may call."""

    services: list[Service]


class UnadvertiseServices(msgspec.Struct, frozen=True, tag_field="op", tag="unadvertiseServices"):
    """``unadvertiseServices``: services gone."""

    serviceIds: list[int]


class ServiceCallFailure(msgspec.Struct, frozen=True, tag_field="op", tag="serviceCallFailure"):
    """``serviceCallFailure``: the call ``callId`` of ``serviceId`` got no response, and why."""

    serviceId: int
    callId: int
    message: str


class ParameterOut(msgspec.Struct, frozen=True, omit_defaults=True):
    """One parameter of ``parameterValues``; no ``value``: it was deleted.

    ``type`` is ``float64`` or ``float64_array`` for floats (JSON writes ``1.0`` as ``1``),
    ``byte_array`` for bytes (``value``: their base64 text).
    """

    name: str
    value: Any | msgspec.UnsetType = msgspec.UNSET
    type: str | None = None


class ParameterValues(
    msgspec.Struct, frozen=True, omit_defaults=True, tag_field="op", tag="parameterValues"
):
    """``parameterValues``: an answer to ``getParameters``/``setParameters``, or an update."""

    parameters: list[ParameterOut]
    id: str | None = None


class PublishedTopic(msgspec.Struct, frozen=True):
    """A topic of the connection graph and the nodes that publish it."""

    name: str
    publisherIds: list[str]


class SubscribedTopic(msgspec.Struct, frozen=True):
    """A topic of the connection graph and the nodes that subscribe to it."""

    name: str
    subscriberIds: list[str]


class AdvertisedService(msgspec.Struct, frozen=True):
    """A service of the connection graph and the node that provides it."""

    name: str
    providerIds: list[str]


class ConnectionGraphUpdate(
    msgspec.Struct, frozen=True, tag_field="op", tag="connectionGraphUpdate"
):
    """``connectionGraphUpdate``: entries new or changed since the last one, and names gone."""

    publishedTopics: list[PublishedTopic]
    subscribedTopics: list[SubscribedTopic]
    advertisedServices: list[AdvertisedService]
    removedTopics: list[str]
    removedServices: list[str]


ServerOp = (
    ServerInfo
    | Status
    | RemoveStatus
    | Advertise
    | Unadvertise
    | AdvertiseServices
    | UnadvertiseServices
    | ServiceCallFailure
    | ParameterValues
    | ConnectionGraphUpdate
)

_encoder = msgspec.json.Encoder()


def encode_op(op: ServerOp) -> bytes:
    """The JSON text of a server op (UTF-8)."""
    return _encoder.encode(op)


def encode_message_data(subscription_id: int, log_time_ns: int, payload: bytes) -> bytes:
    """A binary message data frame (opcode 0x01): header, then the payload as is."""
    return encode_message_header(subscription_id, log_time_ns) + payload


encode_message_header: Final[Callable[[int, int], bytes]] = functools.partial(
    _DATA_HEADER.pack, _MESSAGE_DATA
)
"""``encode_message_header(subscription_id, log_time_ns)``: the 13 bytes of a message
data frame before its payload (opcode, id, log time). A partial of ``struct.pack``, not a
function: it is called per message and subscription of a burst, and so runs no Python frame."""


def encode_service_call_response(
    service_id: int, call_id: int, encoding: str, payload: bytes
) -> bytes:
    """A binary service call response frame (opcode 0x03): header, encoding, then the payload."""
    name = encoding.encode()
    header = struct.pack("<BIII", _SERVICE_CALL_RESPONSE, service_id, call_id, len(name))
    return header + name + payload


class FetchAssetStatus(IntEnum):
    """A ``fetchAssetResponse``'s status."""

    SUCCESS = 0
    ERROR = 1


def encode_fetch_asset_response(request_id: int, data: bytes | None, error: str = "") -> bytes:
    """A binary fetch asset response (opcode 0x04): ``data``, or with None the ``error``."""
    if data is None:
        text = error.encode("utf-8", "replace")
        return (
            _ASSET_HEADER.pack(_FETCH_ASSET_RESPONSE, request_id, FetchAssetStatus.ERROR, len(text))
            + text
        )
    return _ASSET_HEADER.pack(_FETCH_ASSET_RESPONSE, request_id, FetchAssetStatus.SUCCESS, 0) + data


def encode_time(time_ns: int) -> bytes:
    """A binary time frame (opcode 0x02)."""
    return _TIME_FRAME.pack(_TIME, time_ns)


def encode_playback_state(
    status: PlaybackStatusCode, time_ns: int, speed: float, *, did_seek: bool, request_id: str
) -> bytes:
    """A binary playback state frame (opcode 0x05); ``request_id`` "": not an answer.

    ``speed`` is written as a 32-bit float, ``time_ns`` as u64 (clamped at 0).
    """
    name = request_id.encode()
    header = _PLAYBACK_STATE_HEADER.pack(
        _PLAYBACK_STATE, status, max(0, time_ns), speed, did_seek, len(name)
    )
    return header + name
