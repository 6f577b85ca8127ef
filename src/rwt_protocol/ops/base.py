"""Shared pieces of the op models: the base class and the field types.

Every op is a frozen pydantic model validated in strict mode (no coercion: a
JSON ``"5"`` is not an int, ``true`` is not an int) with unknown fields ignored
(spec 1: any JSON object with an ``op`` is a message; extra fields are the
client's business). Wire names are the spec's, verbatim.
"""

from __future__ import annotations

from enum import StrEnum
from functools import cache
from typing import TYPE_CHECKING, Annotated, Any, NamedTuple

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, PlainValidator
from pydantic_core import PydanticCustomError

from ..errors import LocalProtocolError
from ..names import name_problem

if TYPE_CHECKING:
    from collections.abc import Callable

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
    "WireAs",
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


class WireAs:
    """``Annotated`` metadata: the type a field has in the op's msgspec twin (``ops.wire``).

    For a field whose model type msgspec cannot decode (a nested pydantic model,
    ``ops.qos.Qos``): the twin takes ``type`` there and leaves the checks to the model.
    """

    __slots__ = ("type",)

    def __init__(self, type_: Any) -> None:
        """Give the twin's type of the field."""
        self.type = type_


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
    what a peer sends is validated by it (``model_validate``, in
    ``codecs.json.parse_object``), what rwt sends is built by calling it
    (``ServiceResponse(service=..., result=True, values=...)``) and encoded by
    ``codecs.json.op_object``, and the msgspec decoder of the publish hot path
    is generated from it (``ops.wire``).

    Calling a model builds an outgoing op without validating it again: rwt
    builds it from values it holds already (names and ids a peer sent were
    validated on the way in), mypy checks each call's fields and types, and a
    call's cost stays that of a dict (the ops of every reply and status). The
    fields given are the ones sent (``model_fields_set``), ``op`` first, in the
    model's field order, those given as None left out (the spec's optional
    fields are absent rather than null).

    Each model's validator is built when first used, not at import: a server
    pays only for the ops its clients send (benchmarks B11 base memory).
    """

    model_config = ConfigDict(strict=True, frozen=True, extra="ignore", defer_build=True)

    op: str
    """The op's wire name: each model's own, a ``Literal`` with it as the default."""

    def __init__(self, /, **fields: Any) -> None:
        """Build an outgoing op from its fields by wire name, ``op`` excepted (not validated).

        Raises:
            LocalProtocolError: a field the op does not have, or a required
                field missing (a bug in the caller, not the peer's fault; mypy
                finds it first).
        """
        shape = _shape(type(self))
        given = fields.keys()
        values = shape.template.copy()  # op first, then every field in order
        values.update(fields)
        if len(values) != len(shape.template) or not shape.required <= given:
            raise LocalProtocolError(
                f"{shape.op}: unknown fields {sorted(given - shape.template.keys())},"
                f" missing {sorted(shape.required - given)}"
            )
        for name, factory in shape.factories:
            if name not in fields:
                values[name] = factory()
        _set = object.__setattr__
        _set(self, "__dict__", values)
        _set(self, "__pydantic_fields_set__", set(given))
        _set(self, "__pydantic_extra__", None)
        _set(self, "__pydantic_private__", None)

    # pydantic calls a model's own ``__init__`` when it validates, unless marked as
    # its base one (as pydantic's ``RootModel`` marks its own): validation stays pydantic's.
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]


class _Shape(NamedTuple):
    op: str
    template: dict[str, Any]
    """``op``, then each field in order with its default (None for a required one)."""
    required: frozenset[str]
    factories: tuple[tuple[str, Callable[[], Any]], ...]
    """The fields whose default is made per op (``Publish.msg``'s empty dict)."""


@cache
def _shape(model: type[OpModel]) -> _Shape:
    op = model.model_fields["op"].default
    fields = {name: info for name, info in model.model_fields.items() if name != "op"}
    template: dict[str, Any] = {"op": op}
    for name, info in fields.items():
        template[name] = None if info.is_required() or info.default_factory else info.default
    return _Shape(
        op=op,
        template=template,
        required=frozenset(name for name, info in fields.items() if info.is_required()),
        factories=tuple(
            (name, info.default_factory)  # type: ignore[misc]
            for name, info in fields.items()
            if info.default_factory is not None
        ),
    )
