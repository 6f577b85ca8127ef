"""What the protocol's encoders need from a message type (``rwt_protocol.ports.MessageCodec``).

CBOR sends numeric arrays as RFC 8746 typed arrays whose tag depends on the
element type (REF §3.2), which only the type knows: ``typed`` replaces each
numeric array of a message with a numpy array of its element type (numpy
converts a whole list in C). cbor-raw sends the dialect's wire serialization
(REF §3.5): ``serialize`` builds the rosbags object and lets rosbags write CDR
(ROS 2, with the 4-byte encapsulation header) or the ROS 1 format.

Each type's plan is compiled once: a type without numeric arrays at any depth
has no plan, and ``typed`` returns the message itself.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Final

from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.shortcuts import enabled

from .convert import is_time_type
from .names import Dialect
from .primitives import NUMPY_DTYPES
from .spec import ArrayKind, FieldType, is_bytes_base

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from .message import MessageType

__all__ = [
    "CDR_TRAILING_SLACK",
    "WIRE_ENCODINGS",
    "CdrError",
    "WireCodec",
    "check_wire_header",
    "compile_typed",
    "read_cdr",
    "wire_encoding",
    "wire_input",
]

Msg = Mapping[str, object]
_LARGE_VIEW = 64 * 1024
#: The view is for the ``cbor-splice-encode`` shortcut only: cbor2 would write a
#: memoryview as an array of integers, so without the splicer it gets bytes.
_KEEP_VIEW = enabled("cbor-splice-encode")
Typer = Callable[[Msg], Msg]


#: The ``cdr-input-view`` shortcut (shortcuts.py); off, rosbags gets ``bytes`` always.
_VIEW_INPUT = enabled("cdr-input-view")


WIRE_ENCODINGS: Final = {Dialect.ROS2: "cdr", Dialect.ROS1: "ros1"}
"""The name of each dialect's wire form, as Foxglove and MCAP name message encodings."""


def wire_encoding(dialect: Dialect) -> str:
    """The name of ``dialect``'s wire form: ``cdr`` (ROS 2) or ``ros1``."""
    return WIRE_ENCODINGS[dialect]


def wire_input(data: bytes) -> bytes | memoryview:
    """``data`` (a serialized message) as rosbags' deserializers read it fastest.

    rosbags' ``Typestore.deserialize_cdr`` cuts off the 4-byte encapsulation
    header with a slice, which copies a ``bytes`` object but not a view: for a
    1 MB image that copy was half of its 120 us decode. A small message decodes a
    little faster from ``bytes``, so only one of at least 64 KiB becomes a view
    (the ``cdr-input-view`` shortcut, docs/shortcuts.md).
    """
    return memoryview(data) if _VIEW_INPUT and len(data) >= _LARGE_VIEW else data


class CdrError(RemoteProtocolError, ValueError):
    """Bytes that are not a message of the expected type in the dialect's wire form.

    CDR for ROS 2 (the name), the ROS 1 format for ROS 1 (``WireCodec.deserialize``);
    a peer or a publisher of serialized messages sent them. Also a ``ValueError``,
    which rosbags' own errors are.
    """


def check_wire_header(dialect: Dialect, data: bytes | memoryview) -> None:
    """Refuse ``data`` as a serialized message of ``dialect`` by its header alone.

    ROS 2's CDR starts with a 4-byte encapsulation header (little or big
    endian plain CDR, as rmw writes it); the ROS 1 format has none, so any
    bytes pass. The fields are not read: ``read_cdr`` checks them.

    Raises:
        CdrError: a ROS 2 ``data`` shorter than the header, or with another one.
    """
    # per message of a serialized publisher: indexing, not slices (00 00 or 00 01)
    if dialect is not _ROS1 and (len(data) < 4 or data[0] or data[1] > 1):
        raise CdrError("not CDR: no little or big endian CDR encapsulation header")


_ROS1: Final = Dialect.ROS1

#: Bytes after a CDR payload accepted whatever its size (see ``read_cdr``).
CDR_TRAILING_SLACK = 64


def read_cdr(store: Typestore, data: bytes | memoryview, name: str) -> object:
    """Deserialize the CDR message ``data`` of rosbags type ``name``, trailing bytes allowed.

    rosbags' ``Typestore.deserialize_cdr`` refuses more than 3 bytes after the
    payload, but real writers leave more: rmw sizes a serialized message's
    buffer by its estimate, which counts worst-case alignment, so rclpy's
    ``serialize_message`` of a ``sensor_msgs/JointState`` carries 8 bytes past
    its fields. Alignment padding never outweighs the fields it aligns, so up
    to the payload's own size plus ``CDR_TRAILING_SLACK`` bytes may follow it;
    more is not a message of this type (a megabyte of zeros is no goal).

    Raises:
        CdrError: ``data`` has no CDR encapsulation header, is too short or
            malformed for the type, or has more bytes after it than allowed.
        KeyError: the typestore lacks ``name``.
    """
    check_wire_header(Dialect.ROS2, data)
    msgdef = store.get_msgdef(name)
    func = msgdef.deserialize_cdr_le if data[1] else msgdef.deserialize_cdr_be
    try:
        message, used = func(data[4:], 0, msgdef.cls, store)
    except Exception as exc:  # struct, unicode, index and value errors of a short buffer
        raise CdrError(f"cannot deserialize {name}: {exc}") from None
    trailing = len(data) - 4 - used
    if trailing > used + CDR_TRAILING_SLACK:
        raise CdrError(f"{name}: {trailing} bytes after a payload of {used}")
    return message


def _element_dtype(ftype: FieldType, dialect: Dialect) -> str | None:
    """The numpy type name of a primitive array's elements, or None when it stays a list/bytes."""
    if ftype.is_message or is_bytes_base(ftype.base):
        return None
    if ftype.base == "byte":  # an octet in ROS 2, int8 in ROS 1 (REF §4.1)
        return "int8" if dialect is Dialect.ROS1 else "uint8"
    return NUMPY_DTYPES.get(ftype.base)


def _field_typer(
    ftype: FieldType, mtype: MessageType, resolve: Callable[[str], MessageType]
) -> Callable[[object], object] | None:
    if ftype.array is not ArrayKind.NONE:
        dtype = _element_dtype(ftype, mtype.dialect)
        if dtype is not None:
            # Loaded only for types with numeric arrays: an idle server needs no numpy.
            from numpy import asarray  # noqa: PLC0415

            return lambda value: asarray(value, dtype=dtype)
    if not ftype.is_message or is_time_type(ftype):
        return None
    inner = compile_typed(resolve(ftype.base), resolve)
    if inner is None:
        return None
    if ftype.array is ArrayKind.NONE:
        return inner  # type: ignore[return-value]
    return lambda value: [inner(item) for item in value]  # type: ignore[attr-defined]


def compile_typed(mtype: MessageType, resolve: Callable[[str], MessageType]) -> Typer | None:
    """Compile the function that gives a message of ``mtype`` its typed arrays.

    Returns:
        A function mapping a message in the internal form to a shallow copy whose
        numeric arrays (at any depth) are numpy arrays; None when the type has no
        numeric array at any depth. ``uint8``/``char`` arrays stay ``bytes``,
        ``bool``/``string`` arrays stay lists, times stay maps.
    """
    plan = [
        (spec.name, typer)
        for spec in mtype.fields
        if (typer := _field_typer(spec.type, mtype, resolve)) is not None
    ]
    if not plan:
        return None

    def typed(msg: Msg) -> Msg:
        out = dict(msg)
        for name, typer in plan:
            out[name] = typer(msg[name])
        return out

    return typed


class WireCodec:
    """The ``MessageCodec`` of one message type.

    Args:
        mtype: the message type.
        resolve: finds nested message types by canonical name.
        typestore: gives the registry's rosbags typestore (built on first use).
    """

    def __init__(
        self,
        mtype: MessageType,
        resolve: Callable[[str], MessageType],
        typestore: Callable[[], Typestore],
    ) -> None:
        self.mtype = mtype
        self._typer = compile_typed(mtype, resolve)
        self._typestore = typestore
        self._serializer: Callable[[Msg], memoryview] | None = None

    def typed(self, msg: Msg) -> Msg:
        """``msg`` with numeric arrays as numpy arrays (for CBOR typed arrays, REF §3.2)."""
        return msg if self._typer is None else self._typer(msg)

    def serialize(self, msg: Msg) -> bytes | memoryview:
        """The dialect's wire serialization of ``msg`` (for cbor-raw, REF §3.5).

        Returns:
            The bytes; from 64 KiB on, rosbags' read-only view of its own fresh
            buffer, which the CBOR encoder splices without a copy (B4), unless
            that shortcut (``cbor-splice-encode``) is off.

        Raises:
            KeyError: the typestore lacks the type (a definition that failed to load).
        """
        raw = self.serializer()(msg)
        return raw if _KEEP_VIEW and len(raw) >= _LARGE_VIEW else bytes(raw)

    def deserialize(self, data: bytes) -> dict[str, object]:
        """The message in the internal form from the dialect's wire serialization.

        CDR (ROS 2) is read by ``read_cdr`` (trailing bytes allowed), the ROS 1
        format by rosbags; either way the values are checked as a client's are
        (``MessageType.from_python``).

        Raises:
            CdrError: ``data`` is not a message of this type in that form.
        """
        store = self._typestore()
        name = self.mtype.rosbags_name
        ros1 = self.mtype.dialect is Dialect.ROS1
        try:
            if ros1:
                obj = store.deserialize_ros1(data, name)
            else:
                obj = read_cdr(store, wire_input(data), name)
            return self.mtype.from_python(obj)
        except Exception as exc:  # rosbags' and the conversion's assorted errors
            text = getattr(exc, "message", None) or str(exc)
            form = "ros1" if ros1 else "cdr"
            reason = f"{self.mtype.name}: not a {form} message of this type ({text[:200]})"
            raise CdrError(reason) from None

    def serializer(self) -> Callable[[Msg], memoryview]:
        """The function giving rosbags' serialization of a message, as its read-only view.

        Built once per codec from the type's rosbags converter and the
        dialect's rosbags serializer (CDR for ROS 2, the ROS 1 format); a
        recorder calls it for every message (B20).

        Raises:
            KeyError: the typestore lacks the type (a definition that failed to load).
        """
        if self._serializer is None:
            store = self._typestore()
            to_rosbags = self.mtype.to_rosbags_converter(store)
            name = self.mtype.rosbags_name
            ros1 = self.mtype.dialect is Dialect.ROS1
            write = store.serialize_ros1 if ros1 else store.serialize_cdr

            def serialize(msg: Msg) -> memoryview:
                return write(to_rosbags(msg), name)  # type: ignore[arg-type]  # read only

            self._serializer = serialize
        return self._serializer
