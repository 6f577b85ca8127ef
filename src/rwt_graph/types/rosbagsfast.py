"""Generated converters between the internal form and rosbags objects (B20).

``interop.to_rosbags`` and ``interop.from_rosbags`` walk a message type's
fields for every message, asking of each field whether it is an array, a time,
a nested message or a byte; recording and replaying a bag pays that walk for
every message (B20: it cost about as much as rosbags' own CDR serialization).
These functions generate, once per type, Python source that does the same for
that type's fields with no such questions (as ``fastpath`` does for checks):

- to rosbags: each scalar is passed on as it is, each time becomes its
  ``builtin_interfaces`` object, each nested message goes through its own
  generated function, and ``bytes`` of ``uint8``/``char`` arrays become a
  read-only numpy view without a copy;
- from rosbags: ``str``, ``int``, ``float`` and ``bool`` values are taken as
  they are, times become ``sec``/``nanosec`` maps, ``uint8``/``char`` numpy
  arrays become ``bytes`` (one copy), nested messages go through their own
  function.

Every other value (other arrays, ROS 2 ``byte`` and ``wstring``, numpy scalars) is handed to
the general function of ``interop`` for that field, so both paths give the same
result by construction; ``tests/graph/types/test_rosbagsfast.py`` checks it for
every shipped type. The shortcut ``rosbags-converters`` (``RWT_NO_SHORTCUTS``)
turns them off: ``MessageType`` then calls ``interop`` directly.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from .convert import is_time_type, time_keys
from .interop import is_wstring, plain_value, rosbags_value
from .names import Dialect
from .sources import IDL_PLACEHOLDER
from .spec import ArrayKind, FieldSpec, FieldType, is_bytes_base

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from .message import MessageType

__all__ = ["FromFn", "ToFn", "compile_from_rosbags", "compile_to_rosbags"]

ToFn = Callable[[dict[str, object]], object]
FromFn = Callable[[object], dict[str, object]]
Resolve = Callable[[str], "MessageType"]

#: Values rosbags hands out that the internal form keeps as they are.
_PLAIN = frozenset({int, float, str, bool})


class _Names:
    """The objects the generated code refers to, under generated names."""

    def __init__(self) -> None:
        self.values: dict[str, object] = {"_PLAIN": _PLAIN}

    def bind(self, value: object) -> str:
        name = f"_b{len(self.values)}"
        self.values[name] = value
        return name


def _define(label: str, source: str, names: _Names, kind: str) -> Any:
    namespace = dict(names.values)
    exec(compile(source, f"<rwt {kind} converter {label}>", "exec"), namespace)
    return namespace["convert"]


def _is_byte_ros2(ftype: FieldType, dialect: Dialect) -> bool:
    return ftype.base == "byte" and dialect is Dialect.ROS2


def compile_to_rosbags(
    mtype: MessageType, store: Typestore, nested: Callable[[str], ToFn], resolve: Resolve
) -> ToFn:
    """Generate ``msg (internal form) -> rosbags object`` for ``mtype`` and ``store``.

    Args:
        mtype: the message type.
        store: the typestore whose classes are built (``TypeRegistry.typestore()``).
        nested: gives the generated function of a nested type by canonical name.
        resolve: gives a nested type by canonical name (``TypeRegistry.message``),
            for the fields the general path converts.

    Returns:
        A function equal to ``interop.to_rosbags(msg, mtype, store, resolve)``.

    Raises:
        KeyError: ``store`` lacks the type or one of its nested types.
    """
    import numpy as np  # noqa: PLC0415 - rosbags objects hold numpy arrays

    names = _Names()
    args: list[str] = []
    for spec in mtype.fields:
        value = f"msg[{spec.name!r}]"
        expr = _to_expr(spec, value, mtype, store, nested, resolve, names, np)
        args.append(f"{spec.name}={expr}")
    cls: Any = store.types[mtype.rosbags_name]
    if not mtype.fields and IDL_PLACEHOLDER in cls.__dataclass_fields__:
        args.append(f"{IDL_PLACEHOLDER}=0")
    source = f"def convert(msg):\n    return {names.bind(cls)}({', '.join(args)})\n"
    return _define(mtype.name, source, names, "to-rosbags")  # type: ignore[no-any-return]


def _to_expr(
    spec: FieldSpec,
    value: str,
    mtype: MessageType,
    store: Typestore,
    nested: Callable[[str], ToFn],
    resolve: Resolve,
    names: _Names,
    np: Any,
) -> str:
    ftype = spec.type

    def general(v: object, ftype: FieldType = ftype) -> object:
        return rosbags_value(v, ftype, mtype, store, resolve)

    if ftype.array is not ArrayKind.NONE:
        if is_bytes_base(ftype.base):
            frombuffer, uint8 = np.frombuffer, np.uint8

            def array(v: object) -> object:
                # bytes: a read-only view, as the general path gives
                return frombuffer(v, dtype=uint8) if type(v) is bytes else general(v)

            return f"{names.bind(array)}({value})"
        if ftype.is_message and not is_time_type(ftype):
            inner = names.bind(nested(ftype.base))
            return f"[{inner}(item) for item in {value}]"
        return f"{names.bind(general)}({value})"
    if is_time_type(ftype):
        sec_key, nsec_key = time_keys(mtype.dialect)
        kind = "Time" if ftype.base in ("time", "builtin_interfaces/msg/Time") else "Duration"
        cls = names.bind(store.types[f"builtin_interfaces/msg/{kind}"])
        return f"{cls}(sec=(_t := {value})[{sec_key!r}], nanosec=_t[{nsec_key!r}])"
    if ftype.is_message:
        return f"{names.bind(nested(ftype.base))}({value})"
    if _is_byte_ros2(ftype, mtype.dialect) or is_wstring(ftype, mtype.dialect):
        return f"{names.bind(general)}({value})"
    return value


def compile_from_rosbags(
    mtype: MessageType, nested: Callable[[str], FromFn], resolve: Resolve
) -> FromFn:
    """Generate ``rosbags object -> JSON-like dict`` (unchecked) for ``mtype``.

    Args:
        mtype: the message type.
        nested: gives the generated function of a nested type by canonical name.
        resolve: gives a nested type by canonical name (``TypeRegistry.message``),
            for the fields the general path converts.

    Returns:
        A function equal to ``interop.from_rosbags(obj, mtype, resolve)``.
    """
    import numpy as np  # noqa: PLC0415 - rosbags objects hold numpy arrays

    names = _Names()
    items: list[str] = []
    for spec in mtype.fields:
        ftype = spec.type
        value = f"obj.{spec.name}"

        def general(v: object, ftype: FieldType = ftype) -> object:
            return plain_value(v, ftype, mtype.dialect, resolve)

        if ftype.array is not ArrayKind.NONE:
            if is_bytes_base(ftype.base):
                nd = names.bind(np.ndarray)
                other = names.bind(general)
                expr = f"(_v.tobytes() if type(_v := {value}) is {nd} else {other}(_v))"
            elif ftype.is_message and not is_time_type(ftype):
                inner = names.bind(nested(ftype.base))
                expr = f"[{inner}(item) for item in {value}]"
            else:
                expr = f"{names.bind(general)}({value})"
        elif is_time_type(ftype):
            expr = f"{{'sec': (_v := {value}).sec, 'nanosec': _v.nanosec}}"
        elif ftype.is_message:
            expr = f"{names.bind(nested(ftype.base))}({value})"
        elif _is_byte_ros2(ftype, mtype.dialect) or is_wstring(ftype, mtype.dialect):
            expr = f"{names.bind(general)}({value})"
        else:
            expr = f"(_v if type(_v := {value}) in _PLAIN else {names.bind(general)}(_v))"
        items.append(f"{spec.name!r}: {expr}")
    source = f"def convert(obj):\n    return {{{', '.join(items)}}}\n"
    return _define(mtype.name, source, names, "from-rosbags")  # type: ignore[no-any-return]
