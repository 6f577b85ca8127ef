"""Shared pieces of the op models: the base class and the field types.

Every op is a frozen pydantic model validated in strict mode (no coercion: a
JSON ``"5"`` is not an int, ``true`` is not an int) with unknown fields ignored
(spec 1: any JSON object with an ``op`` is a message; extra fields are the
client's business). Wire names are the spec's, verbatim.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, PlainValidator
from pydantic_core import PydanticCustomError

__all__ = [
    "Compression",
    "FragmentSize",
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


def _validate_id(value: object) -> str | int:
    # Spec 1: "an arbitrary string or integer ID"; echoed exactly as sent (D25, D28).
    if isinstance(value, str) or (isinstance(value, int) and not isinstance(value, bool)):
        return value
    raise PydanticCustomError(
        "id_type", "expected str or int, got {got}", {"got": json_type_name(value)}
    )


MessageId = Annotated[str | int, PlainValidator(_validate_id)]
"""An op id: a string or an integer, never a bool (spec 1)."""

NonNegativeInt = Annotated[int, Field(ge=0)]
PositiveInt = Annotated[int, Field(ge=1)]
FragmentSize = Annotated[int, Field(ge=1)]
"""A fragment size in characters (JSON) or bytes (binary); at least 1 (REF §1.4 traps)."""

Seconds = Annotated[float, Field(gt=0, allow_inf_nan=False)]
"""A positive, finite duration in seconds."""

Compression = Literal["none", "png", "cbor", "cbor-raw"]
"""The ``compression`` values of spec 3.3.4."""


class OpModel(BaseModel):
    """Base of every op model: strict, frozen, unknown fields ignored.

    Each model's validator is built when first used, not at import: a server
    pays only for the ops its clients send (issue 8, B11 base memory).
    """

    model_config = ConfigDict(strict=True, frozen=True, extra="ignore", defer_build=True)
