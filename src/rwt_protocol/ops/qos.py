"""The ``qos`` object of ``advertise``, ``publish`` and ``subscribe`` (protocol 2.1.0).

The wire form (spec 4.2.1 of protocol 2.1.0; docs/reference-behaviour.md §13.2), read
as rosbridge_suite 2.7.0/3.3.0/4.2.0 reads it (D62):

- ``history``: ``keep_last`` or ``keep_all``; ``reliability``: ``reliable``,
  ``best_effort`` or ``best_available``; ``durability``: ``transient_local``,
  ``volatile`` or ``best_available``; in any case (``"RELIABLE"`` too), as the
  reference lowers them;
- ``depth``: an integer >= 0 (0: the default depth, ``qos.DEFAULT_DEPTH``);
- ``deadline``, ``lifespan``: seconds (a number >= 0), ``{"secs": S, "nsecs": N}``
  (integers >= 0), or ``"infinite"``; ``deadline`` also ``"best_available"``; 0 is
  no deadline or lifespan (``RMW_DURATION_UNSPECIFIED``), as is a duration past
  ``MAX_DURATION_S``;
- any other field is ignored (``liveliness``, which the spec leaves out), and a
  field left out takes the system default's value, so ``{}`` is the system
  default profile.

A value that breaks these rules refuses the whole op, with a status naming the
field (``$.qos.depth``); nothing is registered with it (D1, D62).
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PlainValidator
from pydantic_core import PydanticCustomError

from ..qos import DEFAULT_DEPTH, Durability, History, QosProfile, Reliability
from .base import INT64_MAX, NonNegativeInt, WireAs, json_type_name

__all__ = ["MAX_DURATION_S", "Qos", "QosField"]

MAX_DURATION_S = 2**63 / 1e9
"""Durations at or past this many seconds (rmw's largest, about 292 years) are infinite."""

_BEST_AVAILABLE = "best_available"


def _lower(value: object) -> object:
    # the reference lowers policy names before looking them up
    return value.lower() if isinstance(value, str) else value


def _seconds(value: object, *, deadline: bool) -> float | str:
    """A duration of the wire as seconds (inf: infinite), or ``best_available``."""
    if isinstance(value, bool):
        pass  # a bool is no number here (JSON true is not 1)
    elif isinstance(value, int | float):
        if math.isnan(value) or value < 0:
            raise PydanticCustomError(
                "qos_duration", "expected a duration >= 0 seconds, got {got}", {"got": value}
            )
        return math.inf if value == 0 or value >= MAX_DURATION_S else float(value)
    elif isinstance(value, dict):
        return _secs_nsecs(value)
    elif isinstance(value, str):
        word = value.lower()
        if word == "infinite":
            return math.inf
        if deadline and word == _BEST_AVAILABLE:
            return _BEST_AVAILABLE
        words = "'infinite' or 'best_available'" if deadline else "'infinite'"
        raise PydanticCustomError(
            "qos_duration", "expected {words}, got {got}", {"words": words, "got": repr(value[:40])}
        )
    raise PydanticCustomError(
        "qos_duration",
        "expected a duration (seconds, an object of secs and nsecs, or 'infinite'), got {got}",
        {"got": json_type_name(value)},
    )


def _secs_nsecs(value: dict[Any, Any]) -> float:
    """``{"secs": S, "nsecs": N}`` as seconds, both integers >= 0 (the reference's form)."""
    parts = [value.get("secs"), value.get("nsecs")]
    if not all(type(part) is int and 0 <= part <= INT64_MAX for part in parts):
        raise PydanticCustomError(
            "qos_duration",
            "expected secs and nsecs as integers >= 0, got {got}",
            {"got": repr(value)[:80]},
        )
    secs, nsecs = parts
    assert isinstance(secs, int) and isinstance(nsecs, int)  # (checked above)
    seconds = secs + nsecs / 1e9
    return math.inf if seconds == 0 or seconds >= MAX_DURATION_S else seconds


def _deadline(value: object) -> float | str | None:
    return None if value is None else _seconds(value, deadline=True)


def _lifespan(value: object) -> float | None:
    if value is None:
        return None
    seconds = _seconds(value, deadline=False)
    assert isinstance(seconds, float)  # (only a deadline may be best_available)
    return seconds


_LOWER = BeforeValidator(_lower)


class Qos(BaseModel):
    """The ``qos`` object as sent (module text); ``profile`` gives what it means.

    Validated as the ops are (``OpModel``): strictly, frozen, unknown fields ignored.
    A policy name's string becomes its enum (``strict=False`` for that field alone).
    """

    model_config = ConfigDict(strict=True, frozen=True, extra="ignore", defer_build=True)

    history: Annotated[Annotated[History, Field(strict=False)] | None, _LOWER] = None
    depth: NonNegativeInt | None = None
    reliability: Annotated[Annotated[Reliability, Field(strict=False)] | None, _LOWER] = None
    durability: Annotated[Annotated[Durability, Field(strict=False)] | None, _LOWER] = None
    deadline: Annotated[float | str | None, PlainValidator(_deadline)] = None
    lifespan: Annotated[float | None, PlainValidator(_lifespan)] = None

    @classmethod
    def of(cls, profile: QosProfile) -> Qos:
        """The ``qos`` object a client sends for ``profile`` (every policy given)."""
        return cls.model_validate(profile.to_json())

    def wire(self) -> dict[str, object]:
        """The object as sent: the fields given, durations as seconds or ``"infinite"``."""
        wire: dict[str, object] = {}
        for name, value in self.__dict__.items():
            if isinstance(value, float) and math.isinf(value):
                wire[name] = "infinite"
            elif value is not None:
                wire[name] = value.value if isinstance(value, StrEnum) else value
        return wire

    def profile(self) -> QosProfile:
        """The profile this object asks for: each field left out at the system default (D62).

        ``keep_all`` keeps ``qos.MAX_DEPTH`` messages at most; a ``depth`` of 0 is
        the default depth.
        """
        deadline = self.deadline
        return QosProfile(
            history=self.history or History.KEEP_LAST,
            depth=self.depth or DEFAULT_DEPTH,
            reliability=self.reliability or Reliability.RELIABLE,
            durability=self.durability or Durability.VOLATILE,
            deadline_s=deadline if isinstance(deadline, float) else math.inf,
            deadline_best_available=deadline == _BEST_AVAILABLE,
            lifespan_s=math.inf if self.lifespan is None else self.lifespan,
        )


QosField = Annotated[Qos | None, WireAs(Any)]
"""An op's optional ``qos`` field (protocol 2.1.0). The msgspec twin of the publish hot
path takes any value there and leaves a frame that has one to the general path
(``codecs.json.decode_publish``), which validates it with this model."""
