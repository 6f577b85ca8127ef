"""Encoding, status and authentication ops: fragment, png, set_level, status, auth."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import MessageId, NonNegativeInt, OpModel, PositiveInt

__all__ = ["Auth", "Fragment", "Png", "SetLevel", "Status"]


class Fragment(OpModel):
    """One part of a message split by its JSON text (spec 3.1.1, D19).

    ``num`` counts from 0; ``total`` is the integer number of parts.
    """

    op: Literal["fragment"] = "fragment"
    id: MessageId
    data: str
    num: NonNegativeInt
    total: PositiveInt


class Png(OpModel):
    """A message carried as a base64 PNG image, possibly in parts (spec 3.1.2, D20)."""

    op: Literal["png"] = "png"
    data: str
    id: MessageId | None = None
    num: NonNegativeInt | None = None
    total: PositiveInt | None = None


class SetLevel(OpModel):
    """Choose which status messages this connection receives (spec 3.2.1, D2)."""

    op: Literal["set_level"] = "set_level"
    level: Literal["info", "warning", "error", "none"]
    id: MessageId | None = None


class Status(OpModel):
    """A status report about an op (spec 3.2.2, D1)."""

    op: Literal["status"] = "status"
    level: Literal["info", "warning", "error"]
    msg: str
    id: MessageId | None = None


class Auth(OpModel):
    """rosauth credentials (ROS 1 edition 3.3.1, D23).

    ``t`` and ``end`` are seconds since the epoch (roslibjs sends floats).
    """

    op: Literal["auth"] = "auth"
    mac: str
    client: str
    dest: str
    rand: str
    t: float = Field(allow_inf_nan=False)
    level: str
    end: float = Field(allow_inf_nan=False)
