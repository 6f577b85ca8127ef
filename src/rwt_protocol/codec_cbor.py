"""The CBOR codec: ops as binary frames (spec 3.1.3, PROTOCOL-DECISIONS D21, D27, REF §3.2).

Outgoing, cbor2 encodes the op map; numeric arrays, which ``MessageCodec.typed``
has turned into numpy arrays, become RFC 8746 typed arrays: a byte string of the
packed little-endian elements under the tag of REF §3.2's table. ``uint8``
arrays are plain byte strings (roslibjs reads both as ``Uint8Array``); floats
are float64; times are maps (``{sec, nanosec}``, ROS 1 ``{secs, nsecs}``) as in
the internal form. numpy packs each array in one call, with no Python loop over
the elements.

Incoming binary frames are CBOR too (D27). Typed arrays in them become lists
again, so the graph checks their values as it checks JSON arrays.
"""

from __future__ import annotations

import io

import cbor2
import numpy as np
import numpy.typing as npt

from .errors import RemoteProtocolError
from .ops.base import json_type_name

__all__ = ["TYPED_ARRAY_TAGS", "decode_cbor", "encode_cbor"]

TYPED_ARRAY_TAGS: dict[str, int] = {
    "uint8": 64,
    "uint16": 69,
    "uint32": 70,
    "uint64": 71,
    "int8": 72,
    "int16": 77,
    "int32": 78,
    "int64": 79,
    "float32": 85,
    "float64": 86,
}
"""numpy element type -> RFC 8746 tag of its little-endian typed array (REF §3.2)."""

_DTYPE_OF_TAG: dict[int, np.dtype[np.generic]] = {
    tag: np.dtype(name).newbyteorder("<") for name, tag in TYPED_ARRAY_TAGS.items()
}
# RFC 8746 big-endian variants (tags 65-68, 73-75, 81-83) and the clamped uint8 (68).
_DTYPE_OF_TAG.update(
    {
        65: np.dtype(">u2"),
        66: np.dtype(">u4"),
        67: np.dtype(">u8"),
        68: np.dtype("u1"),
        73: np.dtype(">i2"),
        74: np.dtype(">i4"),
        75: np.dtype(">i8"),
        81: np.dtype(">f4"),
        82: np.dtype(">f8"),
    }
)

_MAX_DEPTH = 200


def _encode_array(encoder: cbor2.CBOREncoder, value: object) -> None:
    if not isinstance(value, np.ndarray):
        raise TypeError(f"cannot encode {type(value).__name__} as CBOR")
    array: npt.NDArray[np.generic] = value
    name = array.dtype.name
    if name == "uint8":
        encoder.encode(array.tobytes())
    elif name == "bool":
        encoder.encode(array.tolist())
    else:
        tag = TYPED_ARRAY_TAGS[name]
        packed = array.astype(array.dtype.newbyteorder("<"), copy=False).tobytes()
        encoder.encode(cbor2.CBORTag(tag, packed))


def encode_cbor(value: object) -> bytes:
    """Encode an op (a dict in the internal form, numeric arrays as numpy) as CBOR.

    Raises:
        TypeError: a value has no CBOR form (a bug in the caller).
    """
    return cbor2.dumps(value, default=_encode_array)


def _decode_tag(tag: cbor2.CBORTag, immutable: bool) -> object:
    dtype = _DTYPE_OF_TAG.get(tag.tag)
    if dtype is None or not isinstance(tag.value, bytes):
        raise RemoteProtocolError(f"unsupported CBOR tag {tag.tag}")
    if len(tag.value) % dtype.itemsize:
        raise RemoteProtocolError(f"typed array of tag {tag.tag} has a partial element")
    return np.frombuffer(tag.value, dtype=dtype).tolist()


def _refuse_sharing(value: object, immutable: bool) -> object:
    # Tags 28/29 (value sharing) can build cyclic values; ops never need them.
    raise RemoteProtocolError("shared values (CBOR tags 28/29) are not accepted")


_NO_SHARING = {28: _refuse_sharing, 29: _refuse_sharing}


def decode_cbor(frame: bytes) -> object:
    """Decode one binary frame.

    Args:
        frame: one CBOR data item.

    Returns:
        The decoded value; typed arrays (RFC 8746) become lists.

    Raises:
        RemoteProtocolError: not CBOR, trailing bytes, too deeply nested, or an
            unsupported tag.
    """
    stream = io.BytesIO(frame)
    try:
        decoder = cbor2.CBORDecoder(
            stream, tag_hook=_decode_tag, max_depth=_MAX_DEPTH, semantic_decoders=_NO_SHARING
        )
        value = decoder.decode()
    except (cbor2.CBORDecodeError, ValueError, TypeError, RecursionError) as exc:
        if isinstance(exc.__cause__, RemoteProtocolError):
            raise exc.__cause__ from None
        raise RemoteProtocolError(f"invalid CBOR: {_first_line(exc)}") from None
    if stream.tell() != len(frame):
        raise RemoteProtocolError("invalid CBOR: bytes after the first data item")
    return value


def _first_line(exc: BaseException) -> str:
    text = str(exc).splitlines()[0] if str(exc) else json_type_name(exc)
    return text if len(text) <= 80 else text[:77] + "..."
