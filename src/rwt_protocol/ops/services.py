"""Service ops: advertise_service, unadvertise_service, call_service, service_response.

Spec 3.3.6-3.3.9; extras real clients send (``type``, ``timeout``) per REF §2.6.
"""

from __future__ import annotations

from typing import Any, Literal

from .base import (
    CallName,
    Compression,
    CompressionField,
    FragmentSize,
    GraphName,
    MessageId,
    OpModel,
    Seconds,
)

__all__ = ["AdvertiseService", "CallService", "ServiceResponse", "UnadvertiseService"]


class AdvertiseService(OpModel):
    """Offer ``service`` of ``type``; requests arrive as ``call_service`` (spec 3.3.6)."""

    op: Literal["advertise_service"] = "advertise_service"
    service: GraphName
    type: str
    id: MessageId | None = None


class UnadvertiseService(OpModel):
    """Withdraw a service this client advertised (spec 3.3.7)."""

    op: Literal["unadvertise_service"] = "unadvertise_service"
    service: GraphName
    id: MessageId | None = None


class CallService(OpModel):
    """Call ``service``; in the other direction, a request for an advertiser (spec 3.3.8).

    ``args`` is an object (by field name) or a list (positional, D25).
    ``timeout`` is in seconds (rosbridge 2.2); ``type`` is sent by roslibjs and
    only checked against the service's type when given.
    """

    op: Literal["call_service"] = "call_service"
    service: CallName
    args: Any = None
    id: MessageId | None = None
    fragment_size: FragmentSize | None = None
    compression: CompressionField = Compression.NONE
    type: str | None = None
    timeout: Seconds | None = None


class ServiceResponse(OpModel):
    """The answer to a ``call_service`` (spec 3.3.9).

    ``values`` is an object on success and may be an error text when ``result``
    is false (D28).
    """

    op: Literal["service_response"] = "service_response"
    service: GraphName
    result: bool
    values: Any = None
    id: MessageId | None = None
