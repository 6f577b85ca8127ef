"""The Foxglove WebSocket protocol's ops as typed models, parsed and encoded without I/O.

Facts from the Foxglove SDK's server (``rust/foxglove/src/protocol/v1``) and the
``@foxglove/ws-protocol`` client's types (docs/foxglove.md): JSON text ops carry
an ``op`` field; binary frames start with a one-byte opcode and are little-endian.
Server to client: ``serverInfo``, ``status``, ``removeStatus``, ``advertise``,
``unadvertise`` (text), message data (``0x01``: u32 subscription id, u64 log
time in ns, payload), time (``0x02``: u64 ns) and fetch asset response
(``0x04``: u32 request id, u8 status, u32 error length, error text, data).
Client to server: ``subscribe``, ``unsubscribe``, ``advertise``,
``unadvertise``, ``fetchAsset`` (text) and client message data (``0x01``: u32
client channel id, payload).

Every bad input becomes a ``FoxgloveInputError`` whose text goes to the peer as
an error ``status``; the connection goes on (docs/foxglove.md, limits). JSON
text is decoded under the rules of rosbridge frames (``decode_json_text``: at
most 100 levels, no lone surrogate, integers within 64 bits).
"""

from __future__ import annotations

import struct
from enum import IntEnum
from typing import TYPE_CHECKING, Final

import msgspec

from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.errors import RemoteProtocolError

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = [
    "CLIENT_OPS",
    "SUBPROTOCOLS",
    "UNSUPPORTED_OPS",
    "Advertise",
    "Channel",
    "ClientAdvertise",
    "ClientChannel",
    "ClientMessageData",
    "ClientOp",
    "ClientUnadvertise",
    "FetchAsset",
    "FetchAssetStatus",
    "FoxgloveInputError",
    "RemoveStatus",
    "ServerInfo",
    "Status",
    "StatusLevel",
    "Subscribe",
    "Subscription",
    "Unadvertise",
    "Unsubscribe",
    "encode_fetch_asset_response",
    "encode_message_data",
    "encode_op",
    "encode_time",
    "parse_binary",
    "parse_text",
    "select_subprotocol",
]

SUBPROTOCOLS: Final = ("foxglove.sdk.v1", "foxglove.websocket.v1")
"""The WebSocket subprotocols answered: the SDK's name and the older clients' one."""

U32_MAX: Final = 2**32 - 1
_MESSAGE_DATA: Final = 0x01
_TIME: Final = 0x02
_FETCH_ASSET_RESPONSE: Final = 0x04
_SERVICE_CALL_REQUEST: Final = 0x02
_DATA_HEADER = struct.Struct("<BIQ")  # opcode, subscription id, log time (ns)
_CLIENT_DATA_HEADER = struct.Struct("<BI")  # opcode, client channel id
_TIME_FRAME = struct.Struct("<BQ")
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

    subscriptions: list[Subscription]


class Unsubscribe(msgspec.Struct, frozen=True):
    """``unsubscribe``: stop the subscriptions with these ids."""

    subscriptionIds: list[int]


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

    channels: list[ClientChannel]


class ClientUnadvertise(msgspec.Struct, frozen=True):
    """``unadvertise`` from the client: channels it stops publishing on."""

    channelIds: list[int]


class ClientMessageData(msgspec.Struct, frozen=True):
    """Binary client message data (opcode 0x01): one message on a client channel."""

    channel_id: int
    payload: bytes | memoryview


class FetchAsset(msgspec.Struct, frozen=True):
    """``fetchAsset``: the client asks for the file at ``uri``; answered under ``requestId``."""

    uri: str
    requestId: int


ClientOp = (
    Subscribe | Unsubscribe | ClientAdvertise | ClientUnadvertise | FetchAsset | ClientMessageData
)

TextOp = Subscribe | Unsubscribe | ClientAdvertise | ClientUnadvertise | FetchAsset

CLIENT_OPS: Final[dict[str, type[TextOp]]] = {
    "subscribe": Subscribe,
    "unsubscribe": Unsubscribe,
    "advertise": ClientAdvertise,
    "unadvertise": ClientUnadvertise,
    "fetchAsset": FetchAsset,
}
"""The text ops this server handles, by ``op``."""

UNSUPPORTED_OPS: Final = frozenset(
    {
        "getParameters",
        "setParameters",
        "subscribeParameterUpdates",
        "unsubscribeParameterUpdates",
        "subscribeConnectionGraph",
        "unsubscribeConnectionGraph",
    }
)
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
    else:
        for cid in op.channelIds:
            _u32(cid, "client channel id")


def parse_binary(data: bytes) -> ClientMessageData:
    """Parse one binary frame of the client.

    The payload is a view of ``data`` (no copy of a large message).

    Raises:
        FoxgloveInputError: an empty frame, an opcode not handled, or a frame
            shorter than its header.
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
        raise FoxgloveInputError("service calls are not supported by this server")
    raise FoxgloveInputError(f"unknown binary opcode 0x{opcode:02x}")


# ---- server ops -------------------------------------------------------------------


class ServerInfo(msgspec.Struct, frozen=True, tag_field="op", tag="serverInfo"):
    """``serverInfo``: sent first on every connection."""

    name: str
    capabilities: list[str]
    supportedEncodings: list[str]
    metadata: dict[str, str]
    sessionId: str


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


ServerOp = ServerInfo | Status | RemoveStatus | Advertise | Unadvertise

_encoder = msgspec.json.Encoder()


def encode_op(op: ServerOp) -> bytes:
    """The JSON text of a server op (UTF-8)."""
    return _encoder.encode(op)


def encode_message_data(subscription_id: int, log_time_ns: int, payload: bytes) -> bytes:
    """A binary message data frame (opcode 0x01): header, then the payload as is."""
    return _DATA_HEADER.pack(_MESSAGE_DATA, subscription_id, log_time_ns) + payload


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
