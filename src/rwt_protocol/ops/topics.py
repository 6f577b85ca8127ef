"""Topic ops: advertise, unadvertise, publish, subscribe, unsubscribe (spec 3.3.1-3.3.5)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from .base import (
    Compression,
    CompressionField,
    FragmentSize,
    GraphName,
    MessageId,
    NonNegativeInt,
    OpModel,
)
from .qos import QosField

__all__ = ["Advertise", "Publish", "Subscribe", "Unadvertise", "Unsubscribe"]


class Advertise(OpModel):
    """Announce that this client publishes ``topic`` of ``type`` (spec 3.3.1).

    ``latch`` and ``queue_size`` come from the ROS 1 edition; roslibjs and roslibpy
    always send them (REF §2.1). ``qos`` (protocol 2.1.0, ``ops.qos``) replaces
    them when given (D62).
    """

    op: Literal["advertise"] = "advertise"
    topic: GraphName
    type: str
    id: MessageId | None = None
    latch: bool = False
    queue_size: NonNegativeInt = 100
    qos: QosField = None


class Unadvertise(OpModel):
    """Stop publishing ``topic`` (spec 3.3.2)."""

    op: Literal["unadvertise"] = "unadvertise"
    topic: GraphName
    id: MessageId | None = None


class Publish(OpModel):
    """A message on a topic, in either direction (spec 3.3.3).

    ``msg`` is left unvalidated here: the topic's message type checks it, with
    field paths (D9). ``latch`` is the ROS 1 extension (D13). ``type``, from a
    client, advertises the topic for it when it has not (protocol 2.0.0,
    rosbridge_suite 2.6.0/3.2.0/4.1.0; docs/reference-behaviour.md §13.3, D48);
    the server never sends it. ``queue_size`` and ``qos`` (protocol 2.1.0,
    ``ops.qos``) are read only by the publish that advertises (D62).
    """

    op: Literal["publish"] = "publish"
    topic: GraphName
    msg: Any = Field(default_factory=dict)
    id: MessageId | None = None
    latch: bool = False
    type: str | None = None
    queue_size: NonNegativeInt | None = None
    qos: QosField = None


class Subscribe(OpModel):
    """Subscribe to ``topic`` (spec 3.3.4).

    ``throttle_rate`` is in milliseconds; ``fragment_size`` in characters;
    ``queue_length`` in messages (0 = no queueing). ``qos`` (protocol 2.1.0,
    ``ops.qos``): what the subscription asks of the topic (D62-D65).
    """

    op: Literal["subscribe"] = "subscribe"
    topic: GraphName
    type: str | None = None
    id: MessageId | None = None
    throttle_rate: NonNegativeInt = 0
    queue_length: NonNegativeInt = 0
    fragment_size: FragmentSize | None = None
    compression: CompressionField = Compression.NONE
    qos: QosField = None


class Unsubscribe(OpModel):
    """Remove the subscription ``id``, or every subscription to ``topic`` (spec 3.3.5)."""

    op: Literal["unsubscribe"] = "unsubscribe"
    topic: GraphName
    id: MessageId | None = None
