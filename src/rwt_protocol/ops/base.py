"""Shared pieces of the op models: the base class and the field types.

Every op is a frozen pydantic model validated in strict mode (no coercion: a
JSON ``"5"`` is not an int, ``true`` is not an int) with unknown fields ignored
(spec 1: any JSON object with an ``op`` is a message; extra fields are the
client's business). Wire names are the spec's, verbatim.
"""

from __future__ import annotations

from enum import StrEnum
from functools import cache
from typing import Annotated, NamedTuple

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, PlainValidator
from pydantic_core import PydanticCustomError

from ..errors import LocalProtocolError
from ..names import name_problem

__all__ = [
    "INT64_MAX",
    "INT64_MIN",
    "CallName",
    "Compression",
    "CompressionField",
    "FragmentSize",
    "GraphName",
    "Int64",
    "MessageId",
    "NonNegativeInt",
    "OpModel",
    "PositiveInt",
    "Seconds",
    "json_type_name",
]


def json_type_name(value: object) -> str:
    """Name the JSON type of a decoded value: str, int, float, bool, null, array, object."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "int"
    if isinstance(value, float):
        return "float"
    if isinstance(value, str):
        return "str"
    if isinstance(value, list | tuple):
        return "array"
    if isinstance(value, dict):
        return "object"
    return type(value).__name__


INT64_MIN = -(2**63)
INT64_MAX = 2**63 - 1
"""Every integer field of an op, ``id`` included, fits in a signed 64-bit integer:
a peer cannot make the server hold, print or echo a huge number (docs/limits.md)."""


def _validate_id(value: object) -> str | int:
    # Spec 1: "an arbitrary string or integer ID"; echoed exactly as sent (D25, D28).
    if isinstance(value, str):
        return value
    if isinstance(value, int) and not isinstance(value, bool):
        if INT64_MIN <= value <= INT64_MAX:
            return value
        raise PydanticCustomError("id_range", "expected an id within signed 64 bits")
    raise PydanticCustomError(
        "id_type", "expected str or int, got {got}", {"got": json_type_name(value)}
    )


MessageId = Annotated[str | int, PlainValidator(_validate_id)]
"""An op id: a string or an integer, never a bool (spec 1)."""

Int64 = Annotated[int, Field(ge=INT64_MIN, le=INT64_MAX)]
NonNegativeInt = Annotated[int, Field(ge=0, le=INT64_MAX)]
PositiveInt = Annotated[int, Field(ge=1, le=INT64_MAX)]
FragmentSize = Annotated[int, Field(ge=1, le=INT64_MAX)]
"""A fragment size in characters (JSON) or bytes (binary); at least 1 (REF §1.4 traps)."""

Seconds = Annotated[float, Field(gt=0, allow_inf_nan=False)]
"""A positive, finite duration in seconds."""


def _check_name(value: str) -> str:
    problem = name_problem(value)
    if problem is not None:
        raise PydanticCustomError("graph_name", problem)
    return value


def _check_call_name(value: str) -> str:
    # ``service#id`` gives a call its id (D25): only the part before ``#`` is a name.
    _check_name(value.split("#", 1)[0])
    return value


GraphName = Annotated[str, AfterValidator(_check_name)]
"""A topic, service or action name, checked against ROS's naming rules (``names.name_problem``)."""

CallName = Annotated[str, AfterValidator(_check_call_name)]
"""A ``call_service`` service name: a ``GraphName``, optionally followed by ``#id`` (D25)."""


class Compression(StrEnum):
    """The ``compression`` values of spec 3.3.4 (D20, D21)."""

    NONE = "none"
    PNG = "png"
    CBOR = "cbor"
    CBOR_RAW = "cbor-raw"


CompressionField = Annotated[Compression, Field(strict=False)]
"""A ``compression`` field: the wire's string becomes the enum (strict mode would
want the enum itself); any other value is refused."""


class OpModel(BaseModel):
    """Base of every op model: strict, frozen, unknown fields ignored.

    The model is the op's one definition, for both directions and both roles:
    what a peer sends is validated by it (``codecs.json.parse_object``), what rwt
    sends is built by ``frame`` from its field list, and the msgspec decoder of
    the publish hot path is generated from it (``ops.wire``).

    Each model's validator is built when first used, not at import: a server
    pays only for the ops its clients send (benchmarks B11 base memory).
    """

    model_config = ConfigDict(strict=True, frozen=True, extra="ignore", defer_build=True)

    @classmethod
    def frame(cls, **fields: object) -> dict[str, object]:
        """Build this op as an outgoing frame: a dict, ``op`` first, in field order.

        A field given as None is left out (the spec's optional fields are
        absent rather than null); values are not validated (rwt builds them).

        Args:
            **fields: the op's fields by wire name, ``op`` excepted.

        Returns:
            ``{"op": ..., field: value, ...}``, ready for the encoders.

        Raises:
            LocalProtocolError: a field the op does not have, or a required
                field missing (a bug in the caller, not the peer's fault).
        """
        shape = _shape(cls)
        unknown = fields.keys() - shape.names
        missing = shape.required - fields.keys()
        if unknown or missing:
            raise LocalProtocolError(
                f"{shape.op}: unknown fields {sorted(unknown)}, missing {sorted(missing)}"
            )
        out: dict[str, object] = {"op": shape.op}
        for name in shape.order:
            value = fields.get(name)
            if value is not None:
                out[name] = value
        return out

    def to_frame(self) -> dict[str, object]:
        """This op as an outgoing frame (``frame`` of its fields that are not None)."""
        return type(self).frame(**{name: getattr(self, name) for name in _shape(type(self)).order})


class _Shape(NamedTuple):
    op: str
    order: tuple[str, ...]
    names: frozenset[str]
    required: frozenset[str]


@cache
def _shape(model: type[OpModel]) -> _Shape:
    fields = {name: info for name, info in model.model_fields.items() if name != "op"}
    return _Shape(
        op=model.model_fields["op"].default,
        order=tuple(fields),
        names=frozenset(fields),
        required=frozenset(name for name, info in fields.items() if info.is_required()),
    )
