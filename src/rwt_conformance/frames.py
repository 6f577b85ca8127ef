"""What the runner sends and how it reads what it receives.

Received frames are decoded for matching: JSON text as JSON; a CBOR frame (a
WebSocket binary message, a CBOR item on TCP, D21/D22) with cbor2, typed-array
tags (RFC 8746, REF §3.2) shown as ``{"cbor_tag": TAG, "values": [...]}`` so a
case can check both the tag and the numbers; any other tag as ``{"cbor_tag":
TAG, "value": ...}``. Byte strings stay ``bytes`` (patterns ``"<bytes>"``,
``"<bytes:HEX>"``).

A frame nested deeper than ``bounds.MAX_NESTING`` is not decoded: its
``Received`` has a ``problem`` the runner fails the case with (matching and
reporting walk values recursively; docs/conformance.md, "Against a hostile
server").

``auth_op`` makes rosauth ``auth`` ops (D23).
"""

from __future__ import annotations

import io
import json
import math
import secrets
import struct
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cbor2

from rwt_protocol.auth import rosauth_op
from rwt_protocol.codecs.json import check_nesting, op_object
from rwt_protocol.errors import RemoteProtocolError

from .bounds import MAX_NESTING

if TYPE_CHECKING:
    from collections.abc import Mapping

    from .match import JsonValue

__all__ = ["AUTH_VALIDITY_S", "NESTING_PROBLEM", "Received", "auth_op", "decode_frame"]

AUTH_VALIDITY_S = 60
"""Seconds an ``auth`` op made by the runner stays valid."""

_TYPED_ARRAYS = range(64, 88)  # RFC 8746 section 2: 0b010_f_s_e_ll


@dataclass
class Received:
    """A decoded frame: its value, whether it came as CBOR (binary), its size.

    Attributes:
        value: the decoded value (a placeholder when ``problem`` is set).
        binary: True for a CBOR frame.
        size: the frame's length as received (characters of a text frame,
            bytes of a binary one): what the runner counts against a case's budget.
        problem: why the frame cannot be judged (too deeply nested), or None.
    """

    value: JsonValue
    binary: bool
    size: int = 0
    problem: str | None = None


NESTING_PROBLEM = f"the server sent a frame nested deeper than {MAX_NESTING} levels"


def decode_frame(frame: str | bytes) -> Received:
    """Decode a received frame for matching; never raises (undecodable data is shown).

    Text that is not JSON becomes ``{"<not JSON>": its first 200 characters}``,
    CBOR that cbor2 refuses stays ``bytes``; a frame nested deeper than
    ``MAX_NESTING`` gets ``problem`` ``NESTING_PROBLEM`` (checked without
    recursion, as the server core checks its input).
    """
    binary = isinstance(frame, bytes)
    try:
        value = _decode_cbor(frame) if isinstance(frame, bytes) else _decode_json(frame)
        check_nesting(value)
    except (RecursionError, RemoteProtocolError):
        return Received(None, binary, len(frame), NESTING_PROBLEM)
    return Received(value, binary, len(frame))


def _decode_json(frame: str) -> JsonValue:
    """JSON (NaN and Infinity too), or the text shown; RecursionError when too deep."""
    try:
        return json.loads(frame)
    except ValueError:
        return {"<not JSON>": frame[:200]}


def _decode_cbor(frame: bytes) -> JsonValue:
    """CBOR, or the bytes shown; RecursionError when deeper than ``MAX_NESTING``."""
    decoder = cbor2.CBORDecoder(io.BytesIO(frame), tag_hook=_tag, max_depth=MAX_NESTING)
    try:
        return decoder.decode()
    except RecursionError:
        raise
    except Exception as exc:  # anything else cbor2 refuses is shown as bytes
        if "nesting depth" in str(exc):  # cbor2's max_depth, as rwt_protocol.codecs.cbor reads it
            raise RecursionError(str(exc)) from None
        return frame


def _tag(tag: cbor2.CBORTag, _immutable: bool) -> JsonValue:
    if tag.tag in _TYPED_ARRAYS and isinstance(tag.value, bytes):
        values = _typed_array(tag.tag, tag.value)
        if values is not None:
            return {"cbor_tag": tag.tag, "values": values}
    return {"cbor_tag": tag.tag, "value": tag.value}


def _typed_array(tag: int, data: bytes) -> list[JsonValue] | None:
    """The numbers of an RFC 8746 typed array, or None for a form Python cannot unpack."""
    is_float, signed, little = bool(tag & 0x10), bool(tag & 0x08), bool(tag & 0x04)
    size_code = tag & 0x03
    if is_float:
        if size_code == 3:  # binary128
            return None
        code, size = "efd"[size_code], 2 << size_code
    else:
        size = 1 << size_code
        code = "bhiq"[size_code] if signed else "BHIQ"[size_code]
        if tag == 68:  # uint8, clamped arithmetic: the same bytes
            little = True
    if len(data) % size:
        return None
    order = "<" if little else ">"
    return list(struct.unpack(f"{order}{len(data) // size}{code}", data))


def auth_op(secret: str, given: Mapping[str, object], dest: str) -> dict[str, JsonValue]:
    """A rosauth ``auth`` op (D23) valid from now for ``AUTH_VALIDITY_S`` seconds.

    Args:
        secret: the server's shared secret.
        given: fields replacing the made ones (``mac``, ``client``, ``dest``,
            ``rand``, ``level``) and ``t_offset_s``/``end_offset_s``, seconds
            added to the current wall time for ``t`` and ``end``.
        dest: the server's host, the default ``dest``.

    Returns:
        The op; ``t`` and ``end`` are whole seconds since the epoch, and ``mac``
        is rosauth's MAC over the final fields unless ``given`` has one.
    """
    now = math.floor(time.time())
    client = str(given.get("client", "rwt-conformance"))
    dest = str(given.get("dest", dest))
    rand = str(given.get("rand", secrets.token_hex(8)))
    level = str(given.get("level", "admin"))
    t = now + _whole(given.get("t_offset_s", 0))
    end = now + _whole(given.get("end_offset_s", AUTH_VALIDITY_S))
    op = rosauth_op(secret, client=client, dest=dest, rand=rand, t=t, level=level, end=end)
    if "mac" in given:
        op = op.model_copy(update={"mac": str(given["mac"])})
    return op_object(op)


def _whole(value: object) -> int:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return math.floor(value)
    raise ValueError(f"expected a number of seconds, got {value!r}")
