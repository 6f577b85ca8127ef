"""Outgoing encodings: JSON, fragments, PNG, CBOR and cbor-raw (spec 3.1, D19-D21).

Topic messages are encoded once per distinct delivery form: ``MessageEvent.encoded``
caches the frames under a key naming everything they depend on (topic spelling,
D26; compression; fragment size), so a message published to N subscribers is
converted and serialized once per form and the same frame objects are queued for
each subscriber. Intermediate forms (the JSON
text PNG compresses, the typed arrays, the raw serialization) are memoised on
the event too.

Decisions made here (the spec is silent):

- fragment ops carry JSON text; CBOR and cbor-raw frames are binary and are sent
  whole whatever the fragment size (the reference raises instead, REF §3.4);
- a ``png`` op carries the JSON text of the op it replaces; its base64 data is
  split into ``png`` ops with ``id``/``num``/``total`` above the fragment size (D20);
- ``cbor-raw`` for something other than a topic message (a service reply), or
  for a message whose publisher gave no ``MessageCodec``, is sent as ``cbor``;
- a message is cut into at most ``fragments.MAX_PARTS`` parts (D24);
- cbor-raw's ``secs``/``nsecs`` are the wall-clock time of publication, the same
  for every subscriber, so the frame can be shared (REF §3.5 stamps at forwarding);
  its ``bytes`` are the message as it arrived when it arrived serialized
  (``MessageEvent.wire``), else its serialization.

Encoding is total (docs/limits.md): ``safe_op_frames`` never raises. An op that
has no JSON/CBOR form (a string with a lone surrogate, an integer too long to
print, a value without a wire form) is replaced by what its receiver can use:
a reply (``service_response``, ``action_result``) by its failure reply
(``result: false``, the reason in ``values``, D4), anything else by an error
status naming the op.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

from ..codecs.cbor import encode_cbor
from ..codecs.json import encode_json, encode_op, encode_publish_json, op_object
from ..codecs.png import encode_png
from ..framing.fragments import fragment_frames, fresh_id
from ..ops import ActionResult, OpModel, Png, Publish, ServiceResponse, Status
from ..ops.base import Compression
from ..ports import GoalStatus, MessageCodec, MessageEvent
from ..runtime.outbox import OutFrame

__all__ = [
    "EncodeFailure",
    "encode_op_frames",
    "json_frames",
    "png_frames",
    "publish_frames",
    "publish_text_size",
    "safe_op_frames",
    "safe_publish_frames",
]

Frames = tuple[OutFrame, ...]


def _fits(text: bytes, size: int | None) -> bool:
    # Bytes >= characters, so a short byte string fits without decoding it.
    return size is None or len(text) <= size or len(text.decode()) <= size


def json_frames(
    text: bytes, op: str, op_id: object, size: int | None, *, droppable: bool = False
) -> Frames:
    """Send an op's JSON text whole, or as ``fragment`` ops above ``size`` characters (D19).

    Args:
        text: the op's UTF-8 JSON text.
        op: the op's name, for a fresh fragment id.
        op_id: the op's ``id``; the fragments carry it when it is a str or int.
        size: the fragment size in characters, or None for no fragmentation.
        droppable: topic data that may be dropped under pressure (D24).
    """
    if _fits(text, size):
        return (OutFrame(text, False, droppable),)  # positional: see ``_make_publish``
    assert size is not None
    part_id = _part_id(op, op_id)
    parts = fragment_frames(text.decode(), part_id, size)
    return _grouped(parts, droppable)


def png_frames(
    text: bytes, op: str, op_id: object, size: int | None, *, droppable: bool = False
) -> Frames:
    """Send an op's JSON text as a ``png`` op, split into parts above ``size`` (D20, REF §3.3).

    Args:
        text: the op's UTF-8 JSON text.
        op: the op's name, for a fresh id of the parts.
        op_id: the op's ``id``; the parts carry it when it is a str or int.
        size: characters of base64 data per ``png`` op, or None for one op.
        droppable: topic data that may be dropped under pressure (D24).
    """
    data = encode_png(text)
    if size is None or len(data) <= size:
        return (OutFrame(encode_op(Png(data=data)), droppable=droppable),)
    parts = fragment_frames(data, _part_id(op, op_id), size, op="png")
    return _grouped(parts, droppable)


def _grouped(parts: list[bytes], droppable: bool) -> Frames:
    group = object()  # unique per message; the outbox drops a message's parts together
    return tuple(OutFrame(part, droppable=droppable, group=group) for part in parts)


def _part_id(op: str, op_id: object) -> str | int:
    if isinstance(op_id, str) or (isinstance(op_id, int) and not isinstance(op_id, bool)):
        return op_id
    return fresh_id(op)


def publish_frames(
    event: MessageEvent, spelling: str, compression: Compression, fragment_size: int | None
) -> Frames:
    """The frames that deliver ``event`` to a subscriber, made once per form.

    Args:
        event: the published message.
        spelling: the topic name as the subscriber wrote it (D26).
        compression: the subscription's merged compression (D11).
        fragment_size: the merged fragment size in characters, or None.

    Returns:
        The frames, shared by every subscriber asking for the same form.
    """
    binary = compression in ("cbor", "cbor-raw")
    size = None if binary else fragment_size
    key = ("publish", spelling, compression, size)
    return event.encoded(key, lambda: _make_publish(event, spelling, compression, size))


def _make_publish(
    event: MessageEvent, spelling: str, compression: Compression, size: int | None
) -> Frames:
    # OutFrame's arguments positional: keywords to a class cost a dict per call
    # (0.35 us), paid per message of a burst
    if compression == "cbor-raw" and event.codec is not None:
        return (OutFrame(_raw_frame(event, spelling), True, True),)
    if compression in ("cbor", "cbor-raw"):
        msg = event.memo(("memo", "typed"), lambda: _typed(event.msg, event.codec))
        frame = encode_cbor(op_object(Publish(topic=spelling, msg=msg)))
        return (OutFrame(frame, True, True),)
    text = event.memo(("memo", "json", spelling), lambda: _publish_json(event, spelling))
    if compression == "png":
        return png_frames(text, "publish", None, size, droppable=True)
    return json_frames(text, "publish", None, size, droppable=True)


def _publish_json(event: MessageEvent, spelling: str) -> bytes:
    return encode_publish_json(spelling, event.msg)


def publish_text_size(event: MessageEvent, spelling: str) -> int:
    """Bytes of the JSON text of ``event``'s ``publish`` op to ``spelling``; 0 if it has none.

    The text is made once (memoised on the event, as ``publish_frames`` makes
    it for JSON and png subscribers): a png message waiting to be deflated is
    charged its size (``pngout``). Never raises: a message without a JSON form
    is told to its subscriber by ``safe_publish_frames``.
    """
    try:
        text = event.memo(("memo", "json", spelling), lambda: _publish_json(event, spelling))
    except Exception:  # any encoder error, as in ``safe_publish_frames``
        return 0
    return len(text)


def _raw_frame(event: MessageEvent, spelling: str) -> bytes:
    codec = event.codec
    assert codec is not None
    # what arrived serialized (a link's sample, a bag's record) goes on as it came,
    # as rosbridge_suite forwards its raw subscription's bytes (REF §3.5)
    data: bytes | memoryview | None = event.wire
    if data is None:
        data = event.memo(("memo", "raw"), lambda: codec.serialize(event.msg))
    secs = math.floor(event.stamp)
    nsecs = min(round((event.stamp - secs) * 1e9), 999_999_999)
    msg = {"secs": secs, "nsecs": nsecs, "bytes": data}
    return encode_cbor(op_object(Publish(topic=spelling, msg=msg)))


def _typed(msg: Mapping[str, object], codec: MessageCodec | None) -> Mapping[str, object]:
    return msg if codec is None else codec.typed(msg)


def encode_op_frames(
    op: OpModel,
    *,
    compression: Compression = Compression.NONE,
    fragment_size: int | None = None,
    codec: MessageCodec | None = None,
) -> Frames:
    """Encode one op (a reply, a request, a status) in the form its request asked for.

    Args:
        op: the op, its values in the internal form (``codecs.json.op_object``
            makes its JSON object or CBOR map).
        compression: ``none`` (JSON), ``png``, or ``cbor``/``cbor-raw`` (a binary
            CBOR frame; spec 3.3.8 and 3.3.12 let replies ask for compression).
        fragment_size: fragment JSON and PNG above this many characters (D19).
        codec: the type of the op's payload (``values``, else ``msg``), so that
            CBOR sends its numeric arrays as typed arrays; plain arrays without it.

    Returns:
        The frames, none of them droppable (D24).
    """
    message = op_object(op)
    if compression in ("cbor", "cbor-raw"):
        return (OutFrame(encode_cbor(_typed_payload(message, codec)), binary=True),)
    text = encode_json(message)
    op_id = message.get("id")
    if compression == "png":
        return png_frames(text, op.op, op_id, fragment_size)
    return json_frames(text, op.op, op_id, fragment_size)


def _typed_payload(
    message: Mapping[str, object], codec: MessageCodec | None
) -> Mapping[str, object]:
    if codec is None:
        return message
    key = "values" if "values" in message else "msg"
    payload = message.get(key)
    if not isinstance(payload, Mapping):
        return message
    return {**message, key: codec.typed(payload)}


class EncodeFailure(NamedTuple):
    """Why an outgoing op could not be encoded, and what was sent instead.

    Attributes:
        op: the op's name (``service_response``...).
        reason: the encoder's error, one short line.
    """

    op: str
    reason: str


#: The ops a caller waits for: an unencodable one is replaced by a failure reply (D4).
def safe_op_frames(
    op: OpModel,
    *,
    compression: Compression = Compression.NONE,
    fragment_size: int | None = None,
    codec: MessageCodec | None = None,
) -> tuple[Frames, EncodeFailure | None]:
    """``encode_op_frames``, made total: never raises.

    Returns:
        The frames, and None; or, when ``op`` cannot be encoded, frames
        that replace it (a failure reply for ``service_response`` and
        ``action_result``, else an error status, both plain JSON) and the failure.
    """
    try:
        frames = encode_op_frames(
            op, compression=compression, fragment_size=fragment_size, codec=codec
        )
    except Exception as exc:  # any encoder error: TypeError, ValueError, UnicodeError, cbor2's
        failure = EncodeFailure(op.op, _reason(exc))
        return (OutFrame(encode_op(_replacement(op, failure))),), failure
    return frames, None


def safe_publish_frames(
    event: MessageEvent, spelling: str, compression: Compression, fragment_size: int | None
) -> Frames | EncodeFailure:
    """``publish_frames``, made total: the frames, or why the message has no such form.

    The subscriber is then told with an error status and the message skipped;
    the publisher never hears of it (its message was valid for its type).
    """
    try:
        return publish_frames(event, spelling, compression, fragment_size)
    except Exception as exc:  # any encoder error, as in ``safe_op_frames``
        return EncodeFailure("publish", _reason(exc))


def _replacement(op: OpModel, failure: EncodeFailure) -> OpModel:
    """The op sent instead of an unencodable one.

    Only clean strings, bools and small ints go in: a failure reply for a
    ``service_response`` or ``action_result`` (a waiting caller still hears
    back, D4), else an error status.
    """
    text = f"cannot encode the {failure.op}: {failure.reason}"
    op_id = _clean_id(getattr(op, "id", None))
    if isinstance(op, ServiceResponse):
        service = _clean(str(op.service))
        return ServiceResponse(service=service, values=text, result=False, id=op_id)
    if isinstance(op, ActionResult):
        return ActionResult(
            action=_clean(str(op.action)),
            values=text,
            status=int(GoalStatus.ABORTED),
            result=False,
            id="" if op_id is None else op_id,  # ids are clean in practice
        )
    if isinstance(op, Status):
        level = op.level if op.level in _LEVELS else "error"
        return Status(level=level, msg=_clean(str(op.msg)), id=op_id)
    return Status(level="error", msg=f"{failure.op}: {text}", id=op_id)


_LEVELS = ("info", "warning", "error")


def _clean(text: str, limit: int = 200) -> str:
    """``text`` as valid Unicode (lone surrogates escaped), at most ``limit`` characters."""
    text = text if len(text) <= limit else text[: limit - 3] + "..."
    return text.encode("utf-8", "backslashreplace").decode()


def _clean_id(op_id: object) -> str | int | None:
    if isinstance(op_id, str):
        return _clean(op_id, 1000)
    if isinstance(op_id, int) and not isinstance(op_id, bool) and op_id.bit_length() < 64:
        return op_id
    return None


def _reason(exc: BaseException) -> str:
    lines = str(exc).splitlines()
    return _clean(lines[0] if lines else type(exc).__name__, 160)
