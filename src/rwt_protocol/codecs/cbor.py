"""The CBOR codec: ops as binary frames (spec 3.1.3, D21, D27, REF §3.2).

Outgoing, cbor2 encodes the op map; numeric arrays, which ``MessageCodec.typed``
has turned into numpy arrays, become RFC 8746 typed arrays: a byte string of the
packed little-endian elements under the tag of REF §3.2's table. ``uint8``
arrays are plain byte strings (roslibjs reads both as ``Uint8Array``); floats
are float64; times are maps (``{sec, nanosec}``, ROS 1 ``{secs, nsecs}``) as in
the internal form. numpy packs each array in one call, with no Python loop over
the elements.

Incoming binary frames are CBOR too (D27). The server keeps their typed arrays
as read-only numpy arrays over the received bytes (``typed_arrays=True``): the
graph checks a whole array at once by its element type and range, and a
subscriber asking for CBOR gets the same array back without a Python loop
over its elements (B9: a 1.1 M-cell map took 100 ms as a list).
Without it (the Python client) typed arrays become lists.
"""

from __future__ import annotations

import functools
import io
import sys
from typing import TYPE_CHECKING

from ..errors import RemoteProtocolError
from ..ops.base import json_type_name
from ..shortcuts import enabled
from .json import MAX_NESTING, check_nesting, nesting_error

if TYPE_CHECKING:
    import cbor2
    import numpy as np
    import numpy.typing as npt

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


@functools.cache
def _dtype_of_tag() -> dict[int, np.dtype[np.generic]]:
    """RFC 8746 tag -> numpy element type, built on first use (numpy loads lazily)."""
    import numpy as np  # noqa: PLC0415 - a server without CBOR clients never needs numpy

    table = {tag: np.dtype(name).newbyteorder("<") for name, tag in TYPED_ARRAY_TAGS.items()}
    # Big-endian variants (tags 65-67, 73-75, 81-82) and the clamped uint8 (68).
    big = {65: ">u2", 66: ">u4", 67: ">u8", 68: "u1", 73: ">i2", 74: ">i4", 75: ">i8"}
    table.update({tag: np.dtype(code) for tag, code in {**big, 81: ">f4", 82: ">f8"}.items()})
    return table


def _encode_array(encoder: cbor2.CBOREncoder, value: object) -> None:
    import cbor2  # noqa: PLC0415 - loaded by encode_cbor
    import numpy as np  # noqa: PLC0415 - loaded: ``value`` is an array or unknown

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

    Byte strings and numeric arrays of 64 KiB or more within the op's first
    three map levels (an image's ``data`` in ``msg``, cbor-raw's ``bytes``) are
    spliced into the frame with one copy; cbor2 copies such a payload several
    times (4 ms for 4 MiB, B4). The bytes are the same either way (shortcut
    ``cbor-splice-encode``; off, cbor2 encodes the whole op).

    Raises:
        TypeError: a value has no CBOR form (a bug in the caller).
    """
    import cbor2  # noqa: PLC0415 - loaded on first use: JSON-only servers never need it

    if _SPLICE_ENCODE and _has_blob(value, 0):
        return b"".join(_map_parts(value, 0))  # type: ignore[arg-type]
    return cbor2.dumps(value, default=_encode_array)


#: Byte strings and typed arrays at least this long are spliced (see ``encode_cbor``).
_LARGE = 64 * 1024
_MAP_LEVELS = 3
#: The shortcuts of this module (shortcuts.py), chosen once at import.
_SPLICE_ENCODE = enabled("cbor-splice-encode")
_SPLICE_DECODE = enabled("cbor-splice-decode")


def _head(major: int, length: int) -> bytes:
    """The initial bytes of a CBOR item: ``major`` type and ``length`` argument (RFC 8949 §3)."""
    if length < 24:
        return bytes((major << 5 | length,))
    for extra, size in ((24, 1), (25, 2), (26, 4)):
        if length < 1 << (8 * size):
            return bytes((major << 5 | extra,)) + length.to_bytes(size, "big")
    return bytes((major << 5 | 27,)) + length.to_bytes(8, "big")


def _blob_parts(value: object) -> list[bytes | memoryview] | None:
    """A large byte string or 1-D numeric array as CBOR parts, payload uncopied; else None."""
    if type(value) is bytes:
        return [_head(2, len(value)), value] if len(value) >= _LARGE else None
    if type(value) is memoryview and value.nbytes >= _LARGE and value.c_contiguous:
        return [_head(2, value.nbytes), value.cast("B")]  # cbor-raw's serialization
    numpy = sys.modules.get("numpy")  # an array exists only once numpy is loaded
    if numpy is None or not isinstance(value, numpy.ndarray):
        return None
    name = value.dtype.name
    if value.nbytes < _LARGE or value.ndim != 1 or name not in TYPED_ARRAY_TAGS:
        return None
    little = numpy.ascontiguousarray(value.astype(value.dtype.newbyteorder("<"), copy=False))
    data = memoryview(little).cast("B")
    head = [] if name == "uint8" else [_head(6, TYPED_ARRAY_TAGS[name])]  # uint8: plain bytes
    return [*head, _head(2, len(data)), data]


def _is_blob(value: object) -> bool:
    """Whether ``_blob_parts`` splices ``value`` (without building its parts)."""
    if type(value) is bytes:
        return len(value) >= _LARGE
    if type(value) is memoryview:
        return value.nbytes >= _LARGE
    numpy = sys.modules.get("numpy")
    return numpy is not None and isinstance(value, numpy.ndarray) and value.nbytes >= _LARGE


def _has_blob(value: object, level: int) -> bool:
    if type(value) is not dict or level >= _MAP_LEVELS:
        return False
    return any(_is_blob(v) or _has_blob(v, level + 1) for v in value.values())


def _map_parts(value: dict[object, object], level: int) -> list[bytes | memoryview]:
    import cbor2  # noqa: PLC0415 - loaded by encode_cbor

    parts: list[bytes | memoryview] = [_head(5, len(value))]
    for key, item in value.items():
        parts.append(cbor2.dumps(key))
        blob = _blob_parts(item)
        if blob is not None:
            parts += blob
        elif type(item) is dict and level + 1 < _MAP_LEVELS:
            parts += _map_parts(item, level + 1)
        else:
            parts.append(cbor2.dumps(item, default=_encode_array))
    return parts


def _typed_array(tag: cbor2.CBORTag) -> npt.NDArray[np.generic]:
    import numpy as np  # noqa: PLC0415 - loaded by _dtype_of_tag

    dtype = _dtype_of_tag().get(tag.tag)
    if dtype is None or not isinstance(tag.value, bytes):
        raise RemoteProtocolError(f"unsupported CBOR tag {tag.tag}")
    if len(tag.value) % dtype.itemsize:
        raise RemoteProtocolError(f"typed array of tag {tag.tag} has a partial element")
    return np.frombuffer(tag.value, dtype=dtype)  # read-only: a view of immutable bytes


def _tag_as_list(tag: cbor2.CBORTag, immutable: bool) -> object:
    return _typed_array(tag).tolist()


def _tag_as_array(tag: cbor2.CBORTag, immutable: bool) -> object:
    array = _typed_array(tag)
    # Big-endian tags become native order once here, so consumers see one layout.
    return array if array.dtype.isnative else array.astype(array.dtype.newbyteorder("="))


def _refuse_sharing(value: object, immutable: bool) -> object:
    # Tags 28/29 (value sharing) can build cyclic values; ops never need them.
    raise RemoteProtocolError("shared values (CBOR tags 28/29) are not accepted")


#: Bignums (tags 2/3) beyond what CBOR's plain integers hold (64 bits and sign) are
#: refused: no ROS type is wider, and a huge one cannot even be printed as JSON.
_BIGNUM_BYTES = 8


def _bignum(value: object, negative: bool) -> int:
    if not isinstance(value, bytes) or len(value.lstrip(b"\0")) > _BIGNUM_BYTES:
        raise RemoteProtocolError("invalid CBOR: integer out of range (wider than 64 bits)")
    number = int.from_bytes(value, "big")
    return -1 - number if negative else number


_SEMANTIC = {
    2: lambda value, immutable: _bignum(value, False),
    3: lambda value, immutable: _bignum(value, True),
    28: _refuse_sharing,
    29: _refuse_sharing,
}


def decode_cbor(frame: bytes, *, typed_arrays: bool = False) -> object:
    """Decode one binary frame.

    Args:
        frame: one CBOR data item.
        typed_arrays: keep typed arrays (RFC 8746) as read-only 1-D numpy arrays
            in native byte order; otherwise they become lists.

    Returns:
        The decoded value.

    Raises:
        RemoteProtocolError: not CBOR, trailing bytes, nested deeper than
            ``codecs.json.MAX_NESTING`` (``nesting deeper than N``), a bignum wider
            than 64 bits, or an unsupported tag. Text strings are strict UTF-8
            (cbor2), so a lone surrogate is refused too.
    """
    import cbor2  # noqa: PLC0415 - loaded on first use: JSON-only servers never need it

    stream = io.BytesIO(frame)
    try:
        decoder = cbor2.CBORDecoder(
            stream,
            tag_hook=_tag_as_array if typed_arrays else _tag_as_list,
            max_depth=MAX_NESTING,  # cbor2 counts levels as check_nesting does
            semantic_decoders=_SEMANTIC,
        )
        if _SPLICE_DECODE and len(frame) >= _LARGE:
            try:
                value = _Splicer(frame, decoder, stream, typed_arrays).whole()
            except _NotSpliced:
                stream.seek(0)  # let cbor2 decode it, and explain what is wrong
            else:
                check_nesting(value)  # cbor2 counted the levels below the spliced maps only
                return value
        value = decoder.decode()
    except RecursionError:
        raise nesting_error() from None
    except (cbor2.CBORDecodeError, ValueError, TypeError) as exc:
        if isinstance(exc.__cause__, RemoteProtocolError):
            raise exc.__cause__ from None
        if "nesting depth" in str(exc):  # cbor2's max_depth
            raise nesting_error() from None
        raise RemoteProtocolError(f"invalid CBOR: {_first_line(exc)}") from None
    if stream.tell() != len(frame):
        raise RemoteProtocolError("invalid CBOR: bytes after the first data item")
    return value


class _NotSpliced(Exception):
    """The frame has something the splicer leaves to cbor2 (indefinite lengths, errors)."""


class _Splicer:
    """Decode a large frame's first map levels here, large payloads as slices of the frame.

    cbor2 reads a long byte string in 64 KiB chunks and joins them (a guard
    against lengths that lie), 2 ms for 4 MiB; here the length is checked
    against the frame and the payload is one slice: a copy for a byte string,
    a read-only numpy view for a typed array (B4, B6). Every
    other item is decoded by cbor2, so values are the same either way
    (shortcut ``cbor-splice-decode``).
    """

    def __init__(self, frame: bytes, decoder: cbor2.CBORDecoder, stream: io.BytesIO, typed: bool):
        self.frame = frame
        self.view = memoryview(frame)
        self.decoder = decoder
        self.stream = stream
        self.typed = typed

    def whole(self) -> object:
        value, end = self.item(0, 0)
        if end != len(self.frame):
            raise RemoteProtocolError("invalid CBOR: bytes after the first data item")
        return value

    def head(self, pos: int) -> tuple[int, int, int]:
        """``(major type, argument, position after the head)`` of the item at ``pos``."""
        if pos >= len(self.frame):
            raise _NotSpliced
        first = self.frame[pos]
        major, info = first >> 5, first & 31
        if info < 24:
            return major, info, pos + 1
        if info > 27:  # indefinite lengths and reserved values
            raise _NotSpliced
        size = 1 << (info - 24)
        end = pos + 1 + size
        if end > len(self.frame):
            raise _NotSpliced
        return major, int.from_bytes(self.frame[pos + 1 : end], "big"), end

    def item(self, pos: int, level: int) -> tuple[object, int]:
        major, arg, start = self.head(pos)
        if major == 5 and level < _MAP_LEVELS:
            value: dict[object, object] = {}
            at = start
            for _ in range(arg):
                key, at = self.small(at)
                value[key], at = self.item(at, level + 1)
            return value, at
        if major == 2 and arg >= _LARGE:
            if start + arg > len(self.frame):
                raise _NotSpliced
            return bytes(self.view[start : start + arg]), start + arg
        if major == 6 and self.typed:
            array = self.typed_array(arg, start)
            if array is not None:
                return array
        return self.small(pos)

    def typed_array(self, tag: int, pos: int) -> tuple[object, int] | None:
        dtype = _dtype_of_tag().get(tag)
        major, length, start = self.head(pos)
        if dtype is None or major != 2 or length < _LARGE or start + length > len(self.frame):
            return None
        if length % dtype.itemsize:
            raise RemoteProtocolError(f"typed array of tag {tag} has a partial element")
        import numpy as np  # noqa: PLC0415 - loaded by _dtype_of_tag

        array = np.frombuffer(self.frame, dtype, length // dtype.itemsize, start)
        if not array.dtype.isnative:
            array = array.astype(array.dtype.newbyteorder("="))
        return array, start + length

    def small(self, pos: int) -> tuple[object, int]:
        """The item at ``pos``, decoded by cbor2."""
        self.stream.seek(pos)
        value = self.decoder.decode()
        return value, self.stream.tell()


def _first_line(exc: BaseException) -> str:
    text = str(exc).splitlines()[0] if str(exc) else json_type_name(exc)
    return text if len(text) <= 80 else text[:77] + "..."
