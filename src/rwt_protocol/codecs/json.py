r"""The JSON codec: frames to op models and op models to frames.

Decoding uses msgspec (fast, strict JSON). Python's ``json`` is the fallback for
the non-standard literals ``NaN``/``Infinity`` that Python clients such as
roslibpy emit (REF §3.1). Validation goes straight to the model named by
``op`` (faster than trying the union and gives better errors); every failure
becomes a ``RemoteProtocolError`` whose text names the field path
(D1).

Edge rules (docs/limits.md): a frame nested deeper than ``MAX_NESTING`` is
refused with one status ``nesting deeper than N`` (checked without recursion,
and a decoder's own ``RecursionError`` means the same); a string with a lone
surrogate (``"\\ud800"``, which msgspec refuses but ``json`` accepts) is refused,
so every string the server holds can be encoded again.

JSON text carried inside a message (a rosapi parameter value, a client's view of
one, a frame a conformance run receives) is decoded by ``decode_json_text`` under
the same rules, and its integers must fit in 64 bits: no ROS type holds more, and
a longer one cannot even be printed in an error (docs/limits.md, JSON text in
values).
"""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Any, cast

import msgspec
import pybase64
from pydantic import ValidationError

from ..errors import RemoteProtocolError
from ..names import name_problem
from ..ops import OP_MODELS, OpModel, Publish, PublishFrame, PublishView
from ..ops.base import INT64_MAX, INT64_MIN, json_type_name
from ..ops.qos import Qos
from ..shortcuts import enabled

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping

    from pydantic_core import ErrorDetails

__all__ = [
    "MAX_NESTING",
    "check_nesting",
    "decode_json",
    "decode_json_text",
    "decode_publish",
    "decode_publish_one_pass",
    "encode_json",
    "encode_op",
    "encode_other",
    "encode_publish_json",
    "op_object",
    "parse_object",
    "peek_id",
    "valid_unicode",
]

_decoder = msgspec.json.Decoder()

MAX_NESTING = 100
"""The deepest nesting of arrays and objects (maps) accepted in an incoming frame,
JSON or CBOR; the op object itself is level 1 (docs/limits.md). ROS messages
nest a few levels; a deeper frame is refused with ``nesting deeper than 100``."""


def nesting_error() -> RemoteProtocolError:
    """The one error a too deeply nested frame gets (JSON or CBOR)."""
    return RemoteProtocolError(f"nesting deeper than {MAX_NESTING}")


def check_nesting(value: object, openings: int | None = None, *, level: int = 1) -> None:
    """Refuse a decoded value nested deeper than ``MAX_NESTING``.

    Args:
        value: a decoded frame.
        openings: a bound of its nesting known from its text (how many ``[``
            and ``{`` it has), if any: at most ``MAX_NESTING`` and the value is
            not walked.
        level: the level of ``value`` itself (2 for an op's ``msg``).

    Raises:
        RemoteProtocolError: ``nesting deeper than N``.

    The walk goes level by level over the containers only (no recursion),
    linear in the number of values; scalars are only type-tested.
    """
    if openings is not None and openings <= MAX_NESTING:
        return
    items: list[object] = [value]
    depth = level
    while items:
        below: list[object] = []
        for item in items:
            children: Iterable[object]
            if type(item) is dict:
                children = item.values()
            elif type(item) is list:
                children = item
            else:
                continue
            if depth > MAX_NESTING:
                raise nesting_error()
            below += [c for c in children if type(c) is dict or type(c) is list]
        items = below
        depth += 1


def _openings(frame: str | bytes) -> int:
    """An upper bound of the nesting of a JSON text that decoded (its ``[`` and ``{``)."""
    if len(frame) <= 2 * MAX_NESTING:  # each level takes two brackets: no need to count
        return len(frame) // 2
    if isinstance(frame, str):
        return frame.count("[") + frame.count("{")
    return frame.count(b"[") + frame.count(b"{")


_VALID_TOPICS: set[str] = set()
"""Topic names already found valid (at most 4096): the hot path sees few names."""


def _topic_ok(topic: str) -> bool:
    if name_problem(topic) is not None:
        return False
    if len(_VALID_TOPICS) < 4096:
        _VALID_TOPICS.add(topic)
    return True


# A JSON escape that may be half a surrogate pair, or a raw surrogate in a str frame.
_MAYBE_SURROGATE_TEXT = re.compile(r"\\u[dD][89a-fA-F]|[\ud800-\udfff]")
_MAYBE_SURROGATE_BYTES = re.compile(rb"\\u[dD][89a-fA-F]")


def valid_unicode(text: str) -> bool:
    """Whether ``text`` is valid Unicode: no lone surrogate (an unpaired U+D800-U+DFFF).

    Python strings may hold lone surrogates (``json`` decodes the escape into
    one); UTF-8, JSON encoders and CDR refuse them, so a string the server
    keeps must pass this (the one check, used for frames, names and values).
    """
    if text.isascii():
        return True
    try:
        text.encode()
    except UnicodeEncodeError:
        return False
    return True


def _check_unicode(frame: str | bytes, value: object) -> None:
    """Refuse a value holding a string with a lone surrogate (not valid Unicode)."""
    pattern = _MAYBE_SURROGATE_TEXT if isinstance(frame, str) else _MAYBE_SURROGATE_BYTES
    if pattern.search(frame) is None:  # type: ignore[arg-type]
        return
    stack = [value]
    while stack:
        item = stack.pop()
        if type(item) is str:
            if not valid_unicode(item):
                raise RemoteProtocolError(
                    "invalid JSON: a string has a lone surrogate (not valid Unicode)"
                )
        elif type(item) is dict:
            stack.extend(item.keys())
            stack.extend(item.values())
        elif type(item) is list:
            stack.extend(item)


def encode_other(value: object) -> object:
    """Msgspec's hook for values it does not know: numpy arrays and scalars as lists (D27).

    Also an op's ``qos`` object (``ops.qos.Qos``), as sent.

    Raises:
        TypeError: any other value.
    """
    tolist = getattr(value, "tolist", None)  # duck-typed: no numpy import here
    if tolist is None:
        if isinstance(value, Qos):
            return value.wire()
        raise TypeError(f"cannot encode {type(value).__name__} as JSON")
    return tolist()


_encoder = msgspec.json.Encoder(enc_hook=encode_other)
_publish_decoder = msgspec.json.Decoder(PublishFrame)

_EXPECTED = {
    "int_type": "int",
    "int_parsing": "int",
    "string_type": "str",
    "bool_type": "bool",
    "float_type": "number",
    "dict_type": "object",
    "list_type": "array",
    "model_type": "object",
}


def decode_json(frame: str | bytes) -> object:
    """Decode one JSON text.

    Args:
        frame: UTF-8 JSON text.

    Returns:
        The decoded value (dict, list, str, int, float, bool or None).

    Raises:
        RemoteProtocolError: the text is not JSON (not even with NaN/Infinity),
            is nested deeper than ``MAX_NESTING``, or has a string with a lone
            surrogate.
    """
    try:
        value = _decoder.decode(frame)
    except (msgspec.DecodeError, UnicodeError):  # bad UTF-8; a str frame with a surrogate
        value = _fallback(frame)
    except RecursionError:  # msgspec stops at the interpreter's recursion limit
        raise nesting_error() from None
    check_nesting(value, _openings(frame))
    return value


def _fallback(frame: str | bytes) -> object:
    """``json`` for what msgspec refuses: NaN/Infinity, and the error text."""
    if isinstance(frame, bytes):
        try:  # strictly: json.loads would decode CESU-8 surrogate bytes into lone surrogates
            frame = frame.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise RemoteProtocolError(f"invalid JSON: not UTF-8 at byte {exc.start}") from None
    try:
        value = json.loads(frame)
    except RecursionError:
        raise nesting_error() from None
    except (ValueError, TypeError) as exc:
        raise RemoteProtocolError(f"invalid JSON: {_short(str(exc))}") from None
    _check_unicode(frame, value)
    return value


#: The integers a JSON text in a value may hold: int64 and uint64, the widest ROS types.
_INT_RANGE = (INT64_MIN, 2**64 - 1)


def decode_json_text(text: str | bytes, what: str) -> object:
    """Decode JSON text a peer put inside a message, under the rules of frames.

    The text of a rosapi ``set_param`` ``value`` or ``get_param`` default, a
    parameter value a server answers, a frame a conformance run receives: the
    rules of ``decode_json`` (standard JSON plus ``NaN``/``Infinity``, which
    Python clients send, at most ``MAX_NESTING`` levels, no lone surrogate) and
    integers within int64/uint64.

    Args:
        text: the JSON text.
        what: names the text in errors (``"set_param value"``).

    Returns:
        The decoded value (dict, list, str, int, float, bool or None).

    Raises:
        RemoteProtocolError: ``"<what>: invalid JSON: ..."``, ``"<what>: nesting
            deeper than 100"`` or ``"<what>: an integer does not fit in 64 bits"``.
    """
    try:
        value = decode_json(text)
    except RemoteProtocolError as exc:
        raise RemoteProtocolError(f"{what}: {exc.message}") from None
    low, high = _INT_RANGE
    stack = [value]
    while stack:  # nesting is bounded above, but a walk without recursion costs nothing
        item = stack.pop()
        if type(item) is int and not low <= item <= high:
            raise RemoteProtocolError(f"{what}: an integer does not fit in 64 bits")
        if type(item) is dict:
            stack.extend(item.values())
        elif type(item) is list:
            kinds = set(map(type, item))  # a list of scalars: its ints in C-level passes
            if not kinds <= _SCALARS:
                stack.extend(item)
            elif int in kinds and not _ints_fit(item, kinds):
                raise RemoteProtocolError(f"{what}: an integer does not fit in 64 bits")
    return value


_SCALARS = frozenset({int, float, bool, str, type(None)})


def _ints_fit(items: list[object], kinds: set[type]) -> bool:
    """Whether the ints of a list of scalars lie within int64/uint64 (``_INT_RANGE``).

    Numbers only: ``min`` and ``max`` within the range prove it (two C-level passes;
    a NaN they stop at, or a float outside the range, takes the exact check).
    """
    low, high = _INT_RANGE
    numbers = cast("list[float]", items)
    if kinds <= {int, float, bool} and low <= min(numbers) and max(numbers) <= high:
        return True
    return all(low <= item <= high for item in numbers if type(item) is int)


def decode_publish(frame: str | bytes) -> PublishView | None:
    """Decode a ``publish`` op in one msgspec pass (the hot path, benchmarks/README.md B14).

    Returns:
        The op, or None when ``frame`` is not a valid publish op in standard
        JSON (or breaks an edge rule: topic name, nesting), or when the
        ``publish-decode`` shortcut is switched off (shortcuts.py); the caller
        then takes the general path (``decode_json`` and ``parse_object``),
        which explains what is wrong. Never raises.
    """
    if not _PUBLISH_DECODE:  # every caller (server and client sessions) honours the switch
        return None
    return decode_publish_one_pass(frame)


def decode_publish_one_pass(frame: str | bytes) -> PublishView | None:
    """The ``publish-decode`` shortcut itself, whatever the switch: ``decode_publish``'s work.

    Its tests compare it with the general path (tests/protocol/test_publish_fast_path.py).
    """
    # No look at the op first: the typed decode stops at the first field that
    # does not fit (``op`` comes first from roslib and roslibpy), which is
    # cheaper than any scan of the head (B14).
    try:
        op = cast("PublishView", _publish_decoder.decode(frame))
    except (msgspec.DecodeError, UnicodeError, RecursionError):  # also ValidationError
        return None
    if op.topic not in _VALID_TOPICS and not _topic_ok(op.topic):
        return None
    op_id = op.id
    if op_id is not None and type(op_id) is int and not INT64_MIN <= op_id <= INT64_MAX:
        return None
    if op.qos is not None or op.queue_size is not None:  # the model checks these (D62)
        return None
    if len(frame) > 2 * MAX_NESTING:  # shorter frames cannot nest deeper (see _openings)
        try:
            check_nesting(op.msg, _openings(frame), level=2)
        except RemoteProtocolError:
            return None
    return op


#: The ``publish-decode`` shortcut (shortcuts.py), chosen once at import.
_PUBLISH_DECODE = enabled("publish-decode")


def encode_json(value: object) -> bytes:
    """Encode a value as compact UTF-8 JSON.

    ``bytes`` become base64 strings, numpy arrays (CBOR typed arrays kept by
    the server) JSON arrays, and non-finite floats ``null`` (D10).
    """
    return _encoder.encode(value)


def op_object(op: OpModel) -> dict[str, object]:
    """The JSON object (or CBOR map) of an op: what every encoder of an op sends.

    ``op`` first, then the fields the op was built (or received) with, in the
    model's field order, those that are None left out: the spec's optional
    fields are absent rather than null (``ops.base.OpModel``).
    """
    given = op.model_fields_set
    return {
        name: value
        for name, value in op.__dict__.items()
        if value is not None and (name in given or name == "op")
    }


def encode_op(op: OpModel) -> bytes:
    """Encode an op as compact UTF-8 JSON (``encode_json`` of its ``op_object``)."""
    return _encoder.encode(op_object(op))


#: bytes at least this long are base64-encoded by pybase64 instead of msgspec.
_LARGE_BYTES = 64 * 1024
#: The ``json-base64-splice`` shortcut (shortcuts.py); off, msgspec encodes them too.
_SPLICE_BASE64 = enabled("json-base64-splice")


#: The ``publish-encode`` shortcut (shortcuts.py); off, the op is built by its model.
_PUBLISH_ENCODE = enabled("publish-encode")


def _publish_object(topic: str, msg: object) -> dict[str, object]:
    """``op_object(Publish(topic=topic, msg=msg))`` written out: the ``publish-encode`` shortcut.

    Building the model costs 1-2 us, most of a 100 B message's encoding (B1,
    B22 play); tests/protocol/test_shortcuts.py checks both give the same bytes.
    """
    return {"op": "publish", "topic": topic, "msg": msg}


def encode_publish_json(topic: str, msg: Mapping[str, object]) -> bytes:
    """Encode a ``publish`` op (spec 3.3.3) carrying ``msg`` (internal form) as JSON.

    The text is ``encode_op(Publish(topic=topic, msg=msg))``, made faster: the
    op's object written out (shortcut ``publish-encode``), and with fewer copies
    of a large message: byte strings among the message's own fields (an
    image's or a point cloud's ``data``) of 64 KiB or more are base64-encoded
    by pybase64 (several times faster than msgspec's encoder, B6) and spliced
    in as they are (shortcut ``json-base64-splice``).
    """
    large = (
        [k for k, v in msg.items() if type(v) is bytes and len(v) >= _LARGE_BYTES]
        if _SPLICE_BASE64
        else None
    )
    if large:
        ready = dict(msg)
        for key in large:
            data: bytes = msg[key]  # type: ignore[assignment]
            ready[key] = msgspec.Raw(b"".join((b'"', pybase64.b64encode(data), b'"')))
        msg = ready
    if _PUBLISH_ENCODE:
        text = _encoder.encode(_publish_object(topic, msg))
    else:
        text = _encoder.encode(op_object(Publish(topic=topic, msg=msg)))
    # msgspec's output keeps its buffer's spare capacity (up to ~2 KB); a copy of a
    # small frame is exact, so a queue of them holds what the send-buffer limit
    # counts (D24, B8). A large frame's slack is negligible.
    return bytes(memoryview(text)) if len(text) < _LARGE_BYTES else text


def peek_id(obj: object) -> str | int | None:
    """Return the ``id`` of a decoded frame if it is a valid id, for error reports.

    An integer outside signed 64 bits is not a valid id (``ops.base.MessageId``):
    its refusal is not echoed with it.
    """
    if isinstance(obj, dict):
        value = obj.get("id")
        if isinstance(value, str):
            return value
        if isinstance(value, int) and not isinstance(value, bool):
            return value if INT64_MIN <= value <= INT64_MAX else None
    return None


def parse_object(obj: object) -> OpModel:
    """Validate a decoded frame as an op.

    Args:
        obj: a decoded JSON (or CBOR) value.

    Returns:
        The op model for ``obj["op"]``.

    Raises:
        RemoteProtocolError: not an object, no string ``op``, unknown op, or a
            field that does not validate; the text names the field path.
    """
    if not isinstance(obj, dict):
        raise RemoteProtocolError(f"expected a JSON object, got {json_type_name(obj)}")
    op = obj.get("op")
    if op is None:
        raise RemoteProtocolError("missing field at $.op")
    if not isinstance(op, str):
        raise RemoteProtocolError(f"expected str, got {json_type_name(op)} at $.op")
    model = OP_MODELS.get(op)
    if model is None:
        raise RemoteProtocolError(f"unknown op {_short(op)!r}")
    try:
        return model.model_validate(obj)
    except ValidationError as exc:
        raise RemoteProtocolError(f"{op}: {_describe(exc.errors()[0])}") from None


def _describe(error: ErrorDetails) -> str:
    path = "$" + "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in error["loc"])
    kind = error["type"]
    got: Any = error.get("input")
    if kind == "missing":
        return f"missing field at {path}"
    if kind in _EXPECTED:
        return f"expected {_EXPECTED[kind]}, got {json_type_name(got)} at {path}"
    if kind in ("literal_error", "enum"):
        expected = error.get("ctx", {}).get("expected", "")
        return f"expected one of {expected}, got {_short(repr(got))} at {path}"
    if kind in _BOUNDS:
        sign, key = _BOUNDS[kind]
        bound = error.get("ctx", {}).get(key)
        return f"expected a number {sign} {bound}, got {_shown_number(got)} at {path}"
    if kind in ("graph_name", "id_range"):  # our own texts: keep their case
        return f"{error['msg']} at {path}"
    return f"{error['msg'].lower()} at {path}"


_BOUNDS = {
    "greater_than_equal": (">=", "ge"),
    "greater_than": (">", "gt"),
    "less_than_equal": ("<=", "le"),
}


def _shown_number(value: object) -> str:
    # A huge int cannot even be printed (over 4300 digits raises ValueError).
    if isinstance(value, int) and value.bit_length() > 64:
        return f"an integer of {value.bit_length()} bits"
    return _short(repr(value))


def _short(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."
