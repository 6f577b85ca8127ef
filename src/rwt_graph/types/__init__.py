"""The message type registry and the JSON <-> message conversion.

``TypeRegistry`` resolves type strings (D5) to
``MessageType``/``ServiceType``/``ActionType`` objects, read from interface
files and rosbags stores. A ``MessageType`` converts JSON-decoded values to the
internal message form (a plain dict; ``uint8[]`` as bytes; times as
``{sec, nanosec}`` or ``{secs, nsecs}``) under the rules of D7-D10, such that
``msgspec.json.encode`` of that form is rosbridge JSON.
"""

from __future__ import annotations

from .message import ActionType, Converted, MessageType, ServiceType
from .msgparse import DefinitionError, parse_message
from .names import Dialect, InvalidTypeNameError, UnknownTypeError
from .registry import TypeRegistry, codec_for
from .spec import ArrayKind, Constant, FieldSpec, FieldType
from .wire import WireCodec

__all__ = [
    "ActionType",
    "ArrayKind",
    "Constant",
    "Converted",
    "DefinitionError",
    "Dialect",
    "FieldSpec",
    "FieldType",
    "InvalidTypeNameError",
    "MessageType",
    "ServiceType",
    "TypeRegistry",
    "UnknownTypeError",
    "WireCodec",
    "codec_for",
    "parse_message",
]
