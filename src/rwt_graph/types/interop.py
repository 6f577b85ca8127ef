"""Interoperation with rosbags: message objects in and out, field definitions.

rosbags holds messages as dataclasses whose numeric arrays are numpy arrays
(ROS 2 ``byte`` as int8) and whose times are ``builtin_interfaces`` objects in
both dialects. These functions walk a :class:`MessageType` to translate between
those objects and rwt's internal form, so later code can serialize CDR or ROS 1
with a rosbags typestore.

rosbags has no ``wstring``. rmw writes one as a CDR ``sequence<uint32>`` of its
UTF-16 code units (a count, then each unit in 4 bytes, no terminator), so in a
ROS 2 definition each ``wstring`` is the made-up struct :data:`WSTRING_TYPE`
holding that sequence (a struct of one sequence has the sequence's bytes and
alignment; rosbags has no sequence of sequences, which ``wstring[]`` would
need). rwt's own form keeps the text as a ``str``; the functions here turn it
into that struct and back.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Nodetype

from .convert import is_time_type, time_keys
from .names import Dialect
from .primitives import NUMPY_DTYPES
from .sources import IDL_PLACEHOLDER
from .spec import ArrayKind, FieldType, is_bytes_base
from .wire import CdrError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from .message import MessageType

__all__ = [
    "WSTRING_DEFINITION",
    "WSTRING_TYPE",
    "fielddefs",
    "from_rosbags",
    "is_wstring",
    "plain_value",
    "rosbags_value",
    "to_rosbags",
]

Resolve = Callable[[str], "MessageType"]

# rosbags keeps ``byte`` arrays as int8 and ``char`` arrays as uint8, in both dialects
_DTYPES: dict[str, str] = {**NUMPY_DTYPES, "bool": "bool", "char": "uint8", "byte": "int8"}

#: The rosbags name of the struct that carries one ROS 2 ``wstring`` (see the module text).
WSTRING_TYPE = "rwt_graph/msg/WstringUnits"
#: Its rosbags definition ``(constants, fields)``: ``uint32[] units``.
WSTRING_DEFINITION: tuple[list[object], list[object]] = (
    [],
    [("units", (Nodetype.SEQUENCE, ((Nodetype.BASE, ("uint32", 0)), 0)))],
)


def is_wstring(ftype: FieldType, dialect: Dialect) -> bool:
    """Whether ``ftype`` (or its element) is a ``wstring`` carried as :data:`WSTRING_TYPE`.

    ROS 1 has no ``wstring``: in a ROS 1 definition it stays a ``string``.
    """
    return ftype.base == "wstring" and dialect is Dialect.ROS2


def wstring_units(text: str, store: Typestore) -> object:
    """The :data:`WSTRING_TYPE` object of ``text``: its UTF-16 code units as uint32.

    A lone surrogate passes as its own code unit, as a ``str`` may hold one.
    """
    import numpy as np  # noqa: PLC0415 - rosbags objects hold numpy arrays

    units = np.frombuffer(text.encode("utf-16-le", "surrogatepass"), dtype="<u2")
    return store.types[WSTRING_TYPE](units=units.astype(np.uint32))


def wstring_text(obj: object) -> str:
    """The text of a :data:`WSTRING_TYPE` object a peer's CDR gave.

    Raises:
        CdrError: a code unit is above 0xFFFF or the units are not UTF-16 (a
            lone surrogate): not a wstring rmw writes.
    """
    units = obj.units  # type: ignore[attr-defined]
    if len(units) and int(units.max()) > 0xFFFF:
        raise CdrError("a wstring code unit above 0xFFFF")
    try:
        return units.astype("<u2").tobytes().decode("utf-16-le")  # type: ignore[no-any-return]
    except UnicodeDecodeError as exc:
        raise CdrError(f"a wstring that is not UTF-16 ({exc.reason})") from None


def plain_value(value: object, ftype: FieldType, dialect: Dialect, resolve: Resolve) -> object:
    """One field's value of a rosbags object as a JSON-like value (unchecked)."""
    import numpy as np  # noqa: PLC0415 - loaded already: rosbags objects hold numpy arrays

    if ftype.array is not ArrayKind.NONE:
        if isinstance(value, np.ndarray):
            if is_bytes_base(ftype.base):
                return value.tobytes()
            if ftype.base == "byte" and dialect is Dialect.ROS2:
                return value.astype(np.int8).view(np.uint8).tolist()
            return value.tolist()
        if isinstance(value, bytes | bytearray):
            return bytes(value)
        if is_wstring(ftype, dialect):
            return [wstring_text(item) for item in value]  # type: ignore[attr-defined]
        element = ftype.element
        return [plain_value(item, element, dialect, resolve) for item in value]  # type: ignore[attr-defined]
    if is_time_type(ftype):
        return {"sec": value.sec, "nanosec": value.nanosec}  # type: ignore[attr-defined]
    if ftype.is_message:
        return from_rosbags(value, resolve(ftype.base), resolve)
    if is_wstring(ftype, dialect):
        return wstring_text(value)
    if isinstance(value, np.generic):
        value = value.item()
    if ftype.base == "byte" and dialect is Dialect.ROS2 and isinstance(value, int):
        return value & 0xFF
    return value


def from_rosbags(obj: object, mtype: MessageType, resolve: Resolve) -> dict[str, object]:
    """Turn a rosbags message object of ``mtype`` into JSON-like values (unchecked)."""
    return {
        spec.name: plain_value(getattr(obj, spec.name), spec.type, mtype.dialect, resolve)
        for spec in mtype.fields
    }


def rosbags_value(
    value: object, ftype: FieldType, mtype: MessageType, store: Typestore, resolve: Resolve
) -> object:
    """One field's value of ``mtype`` (internal form) as its rosbags object takes it."""
    import numpy as np  # noqa: PLC0415 - only cbor-raw and embedding callers need it

    if ftype.array is not ArrayKind.NONE:
        if ftype.base in _DTYPES:
            if isinstance(value, bytes):  # a read-only view: serializing reads it only
                return np.frombuffer(value, dtype=np.uint8)
            if ftype.base == "byte" and mtype.dialect is Dialect.ROS2:
                return np.asarray(value, dtype=np.uint8).view(np.int8)
            return np.asarray(value, dtype=_DTYPES[ftype.base])
        if is_wstring(ftype, mtype.dialect):
            return [wstring_units(text, store) for text in value]  # type: ignore[attr-defined]
        element = ftype.element
        return [rosbags_value(v, element, mtype, store, resolve) for v in value]  # type: ignore[attr-defined]
    if is_time_type(ftype):
        sec_key, nsec_key = time_keys(mtype.dialect)
        kind = "Time" if ftype.base in ("time", "builtin_interfaces/msg/Time") else "Duration"
        cls = store.types[f"builtin_interfaces/msg/{kind}"]
        return cls(sec=value[sec_key], nanosec=value[nsec_key])  # type: ignore[index]
    if ftype.is_message:
        return to_rosbags(value, resolve(ftype.base), store, resolve)  # type: ignore[arg-type]
    if is_wstring(ftype, mtype.dialect):
        return wstring_units(value, store)  # type: ignore[arg-type]
    if ftype.base == "byte" and mtype.dialect is Dialect.ROS2:
        return int(np.array(value, dtype=np.uint8).view(np.int8))
    return value


def to_rosbags(
    msg: dict[str, object], mtype: MessageType, store: Typestore, resolve: Resolve
) -> object:
    """Build the rosbags object of a message in the internal form.

    Raises:
        KeyError: ``store`` lacks the type (use ``TypeRegistry.typestore()``).
    """
    cls: Any = store.types[mtype.rosbags_name]
    kwargs = {
        spec.name: rosbags_value(msg[spec.name], spec.type, mtype, store, resolve)
        for spec in mtype.fields
    }
    if not mtype.fields and IDL_PLACEHOLDER in cls.__dataclass_fields__:
        kwargs[IDL_PLACEHOLDER] = 0
    return cls(**kwargs)


def _node(ftype: FieldType, dialect: Dialect, resolve: Resolve) -> tuple[object, object]:
    if ftype.array is not ArrayKind.NONE:
        element = _node(ftype.element, dialect, resolve)
        if ftype.array is ArrayKind.FIXED:
            return (Nodetype.ARRAY, (element, ftype.length))
        return (Nodetype.SEQUENCE, (element, ftype.length or 0))
    if is_time_type(ftype):
        kind = "Time" if ftype.base in ("time", "builtin_interfaces/msg/Time") else "Duration"
        return (Nodetype.NAME, f"builtin_interfaces/msg/{kind}")
    if ftype.is_message:
        return (Nodetype.NAME, resolve(ftype.base).rosbags_name)
    if is_wstring(ftype, dialect):
        return (Nodetype.NAME, WSTRING_TYPE)
    base = "string" if ftype.base == "wstring" else ftype.base
    return (Nodetype.BASE, (base, ftype.string_bound or 0))


def fielddefs(mtype: MessageType, resolve: Resolve) -> tuple[list[object], list[object]]:
    """The rosbags ``(constants, fields)`` definition of a message type.

    A ROS 2 ``wstring`` refers to :data:`WSTRING_TYPE`, which the store must
    hold too (``WSTRING_DEFINITION``).
    """
    consts: list[object] = [(c.name, c.type, c.value) for c in mtype.constants]
    fields: list[object] = [
        (spec.name, _node(spec.type, mtype.dialect, resolve)) for spec in mtype.fields
    ]
    if not fields and mtype.dialect is Dialect.ROS2:
        fields.append((IDL_PLACEHOLDER, (Nodetype.BASE, ("uint8", 0))))
    return consts, fields
