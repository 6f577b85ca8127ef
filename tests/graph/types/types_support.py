"""Helpers of the type registry tests (imported by name: tests have no packages)."""

from __future__ import annotations

import math
from pathlib import Path

import msgspec

from rwt_graph.types import MessageType

DATA = Path(__file__).resolve().parent.parent / "data" / "interfaces"
NOW = 1_700_000_000.25


def same(a: object, b: object) -> bool:
    """Equality where NaN equals NaN and types must match (1 != 1.0 != True)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return (math.isnan(a) and math.isnan(b)) or a == b  # type: ignore[arg-type]
    if isinstance(a, dict):
        return list(a) == list(b) and all(same(a[k], b[k]) for k in a)  # type: ignore[call-overload]
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))  # type: ignore[arg-type]
    return a == b


def roundtrip(mtype: MessageType, msg: dict[str, object]) -> dict[str, object]:
    """Encode the internal form as rosbridge JSON and convert it back."""
    decoded = msgspec.json.decode(msgspec.json.encode(msg))
    converted = mtype.from_json(decoded, path="$.msg", now=NOW)
    assert converted.missing == ()
    return converted.msg
