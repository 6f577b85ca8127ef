"""Topic ops: advertise, unadvertise, publish, subscribe, unsubscribe (spec 3.3.1-3.3.5)."""

from __future__ import annotations

from typing import Any, Literal

import msgspec
from pydantic import Field

from .base import (
    Compression,
    FragmentSize,
    GraphName,
    MessageId,
    NonNegativeInt,
    OpModel,
)

__all__ = ["Advertise", "Publish", "PublishFrame", "Subscribe", "Unadvertise", "Unsubscribe"]


class Advertise(OpModel):
    """Announce that this client publishes ``topic`` of ``type`` (spec 3.3.1).

    ``latch`` and ``queue_size`` come from the ROS 1 edition; roslibjs and roslibpy
    always send them (REF §2.1).
    """

    op: Literal["advertise"] = "advertise"
    topic: GraphName
    type: str
    id: MessageId | None = None
    latch: bool = False
    queue_size: NonNegativeInt = 100


class Unadvertise(OpModel):
    """Stop publishing ``topic`` (spec 3.3.2)."""

    op: Literal["unadvertise"] = "unadvertise"
    topic: GraphName
    id: MessageId | None = None


class Publish(OpModel):
    """A message on a topic, in either direction (spec 3.3.3).

    ``msg`` is left unvalidated here: the topic's message type checks it, with
    field paths (PROTOCOL-DECISIONS D9). ``latch`` is the ROS 1 extension (D13).
    """

    op: Literal["publish"] = "publish"
    topic: GraphName
    msg: Any = Field(default_factory=dict)
    id: MessageId | None = None
    latch: bool = False


class PublishFrame(msgspec.Struct, frozen=True):
    """``Publish`` as msgspec decodes it straight from JSON: the publish hot path (benchmarks B14).

    The same fields, defaults and checks as ``Publish`` (``topic`` a string,
    ``id`` a string or an integer but not a bool, ``latch`` a bool, unknown
    fields ignored), done in C while decoding instead of by pydantic after it;
    ``codec.decode_publish`` adds the edge rules (topic name, ``id`` range, nesting).
    A frame this cannot decode goes through the general path, which gives the
    error its field path (D1), so both paths accept and refuse the same frames.
    """

    op: Literal["publish"]  # required: a frame without ``op`` is refused (D1)
    topic: str  # its name rules are checked by ``codec.decode_publish``
    msg: Any = msgspec.field(default_factory=dict)
    id: str | int | None = None  # its 64-bit range is checked by ``codec.decode_publish``
    latch: bool = False


class Subscribe(OpModel):
    """Subscribe to ``topic`` (spec 3.3.4).

    ``throttle_rate`` is in milliseconds; ``fragment_size`` in characters;
    ``queue_length`` in messages (0 = no queueing).
    """

    op: Literal["subscribe"] = "subscribe"
    topic: GraphName
    type: str | None = None
    id: MessageId | None = None
    throttle_rate: NonNegativeInt = 0
    queue_length: NonNegativeInt = 0
    fragment_size: FragmentSize | None = None
    compression: Compression = "none"


class Unsubscribe(OpModel):
    """Remove the subscription ``id``, or every subscription to ``topic`` (spec 3.3.5)."""

    op: Literal["unsubscribe"] = "unsubscribe"
    topic: GraphName
    id: MessageId | None = None
