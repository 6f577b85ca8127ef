"""Interoperation with rosbags: message objects in and out, field definitions.

rosbags holds messages as dataclasses whose numeric arrays are numpy arrays
(ROS 2 ``byte`` as int8) and whose times are ``builtin_interfaces`` objects in
both dialects. These functions walk a :class:`MessageType` to translate between
those objects and rwt's internal form, so later code can serialize CDR or ROS 1
with a rosbags typestore.
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

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from .message import MessageType

__all__ = ["fielddefs", "from_rosbags", "plain_value", "rosbags_value", "to_rosbags"]

Resolve = Callable[[str], "MessageType"]

# rosbags keeps ``byte`` arrays as int8 and ``char`` arrays as uint8, in both dialects
_DTYPES: dict[str, str] = {**NUMPY_DTYPES, "bool": "bool", "char": "uint8", "byte": "int8"}


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
        element = ftype.element
        return [plain_value(item, element, dialect, resolve) for item in value]  # type: ignore[attr-defined]
    if is_time_type(ftype):
        return {"sec": value.sec, "nanosec": value.nanosec}  # type: ignore[attr-defined]
    if ftype.is_message:
        return from_rosbags(value, resolve(ftype.base), resolve)
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
        element = ftype.element
        return [rosbags_value(v, element, mtype, store, resolve) for v in value]  # type: ignore[attr-defined]
    if is_time_type(ftype):
        sec_key, nsec_key = time_keys(mtype.dialect)
        kind = "Time" if ftype.base in ("time", "builtin_interfaces/msg/Time") else "Duration"
        cls = store.types[f"builtin_interfaces/msg/{kind}"]
        return cls(sec=value[sec_key], nanosec=value[nsec_key])  # type: ignore[index]
    if ftype.is_message:
        return to_rosbags(value, resolve(ftype.base), store, resolve)  # type: ignore[arg-type]
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


def _node(ftype: FieldType, resolve: Resolve) -> tuple[object, object]:
    if ftype.array is not ArrayKind.NONE:
        element = _node(ftype.element, resolve)
        if ftype.array is ArrayKind.FIXED:
            return (Nodetype.ARRAY, (element, ftype.length))
        return (Nodetype.SEQUENCE, (element, ftype.length or 0))
    if is_time_type(ftype):
        kind = "Time" if ftype.base in ("time", "builtin_interfaces/msg/Time") else "Duration"
        return (Nodetype.NAME, f"builtin_interfaces/msg/{kind}")
    if ftype.is_message:
        return (Nodetype.NAME, resolve(ftype.base).rosbags_name)
    base = "string" if ftype.base == "wstring" else ftype.base
    return (Nodetype.BASE, (base, ftype.string_bound or 0))


def fielddefs(mtype: MessageType, resolve: Resolve) -> tuple[list[object], list[object]]:
    """The rosbags ``(constants, fields)`` definition of a message type."""
    consts: list[object] = [(c.name, c.type, c.value) for c in mtype.constants]
    fields: list[object] = [(spec.name, _node(spec.type, resolve)) for spec in mtype.fields]
    if not fields and mtype.dialect is Dialect.ROS2:
        fields.append((IDL_PLACEHOLDER, (Nodetype.BASE, ("uint8", 0))))
    return consts, fields
