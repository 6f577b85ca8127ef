"""Parameter values as ROS 2's ``rcl_interfaces/msg/ParameterValue``, both ways.

One conversion for every link that reaches ROS 2 nodes' parameter services
(the Zenoh link, the ROS 2 link). ROS 2 parameters keep their type; so does
rwt's store.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .values import ParameterError

if TYPE_CHECKING:
    from ..types import MessageType
    from .values import ParamValue

__all__ = ["PARAM_SERVICES", "from_wire", "to_wire", "type_code"]

PARAM_SERVICES = {
    "list_parameters": "rcl_interfaces/srv/ListParameters",
    "get_parameters": "rcl_interfaces/srv/GetParameters",
    "set_parameters": "rcl_interfaces/srv/SetParameters",
    "describe_parameters": "rcl_interfaces/srv/DescribeParameters",
    "get_parameter_types": "rcl_interfaces/srv/GetParameterTypes",
    "set_parameters_atomically": "rcl_interfaces/srv/SetParametersAtomically",
}
"""A ROS 2 node's parameter services, as rclpy's ``ParameterService`` offers them:
``<node>/<part>`` of each type."""

# rcl_interfaces/msg/ParameterType
_NOT_SET, _BOOL, _INTEGER, _DOUBLE, _STRING = 0, 1, 2, 3, 4
_BYTES, _BOOLS, _INTEGERS, _DOUBLES, _STRINGS = 5, 6, 7, 8, 9
_FIELDS = {
    _BOOL: "bool_value",
    _INTEGER: "integer_value",
    _DOUBLE: "double_value",
    _STRING: "string_value",
    _BYTES: "byte_array_value",
    _BOOLS: "bool_array_value",
    _INTEGERS: "integer_array_value",
    _DOUBLES: "double_array_value",
    _STRINGS: "string_array_value",
}


_ARRAYS = {
    frozenset({bool}): _BOOLS,
    frozenset({int}): _INTEGERS,
    frozenset({float}): _DOUBLES,
    frozenset({int, float}): _DOUBLES,
    frozenset({str}): _STRINGS,
    frozenset(): _STRINGS,  # an empty array: rclpy's type of []
}


def type_code(value: object) -> int:
    """The ``ParameterType`` code of a value of rwt's store.

    An array's items are looked at by their exact types, in one C-level pass
    (the store holds exact ``bool``, ``int``, ``float`` and ``str`` items).

    Raises:
        ParameterError: the value has no ROS 2 parameter type.
    """
    if isinstance(value, bool):
        return _BOOL
    if isinstance(value, int):
        return _INTEGER
    if isinstance(value, float):
        return _DOUBLE
    if isinstance(value, str):
        return _STRING
    if isinstance(value, bytes | bytearray):
        return _BYTES
    if isinstance(value, list | tuple):
        code = _ARRAYS.get(frozenset(map(type, value)))
        if code is not None:
            return code
    raise ParameterError(f"a value of type {type(value).__name__} is no ROS 2 parameter")


def to_wire(value_type: MessageType, value: ParamValue) -> dict[str, object]:
    """``value`` as a ``ParameterValue`` (``value_type``) in the internal form.

    Raises:
        ParameterError: the value has no ROS 2 parameter type.
    """
    msg = value_type.default()
    kind = type_code(value)
    msg["type"] = kind
    msg[_FIELDS[kind]] = bytes(value) if kind == _BYTES else value  # type: ignore[arg-type]
    return msg


def from_wire(msg: dict[str, object]) -> object:
    """The value of a ``ParameterValue``; None when NOT_SET; a byte array as ``bytes``.

    The internal form holds ``byte[]`` as a list of octets (ints); the store tells
    a byte array from an integer array by its type, so it gets ``bytes``. Another
    array comes as a tuple, as the store holds it (so a copy compares equal).

    Raises:
        ParameterError: an unknown type code, or a byte array with an item
            that is no octet.
    """
    kind = msg.get("type")
    if kind == _NOT_SET:
        return None
    name = _FIELDS.get(kind) if isinstance(kind, int) else None
    if name is None:
        raise ParameterError(f"unknown parameter type {kind!r}")
    value = msg[name]
    if kind == _BYTES:
        return _octets(value)
    return tuple(value) if isinstance(value, list) else value


def _octets(value: object) -> bytes:
    """The bytes of a ``byte_array_value`` (a list of octets in the internal form).

    Raises:
        ParameterError: not a sequence of ints 0-255.
    """
    if isinstance(value, list | tuple | bytes | bytearray):  # never bytes(n): n zero bytes
        try:
            return bytes(value)
        except (TypeError, ValueError):
            pass
    raise ParameterError("a byte array parameter holds an item that is no octet")
