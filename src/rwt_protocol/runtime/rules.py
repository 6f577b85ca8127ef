"""The per-client rules every protocol's connection is bound by (docs/limits.md, "Per connection").

``ClientRules`` holds what the connection runtime enforces whatever protocol a
client speaks: its send buffer and the slow-consumer rule (D24), its hold budget
(input backpressure), the access rules and authenticator, the call timeout, the
caps on what it holds, and the idle timeout. rosbridge's ``SessionConfig``
(``rwt_protocol.server.session``) extends it with rosbridge's own settings; the
Foxglove protocol takes it as it is, with its own section beside it
(``rwt_foxglove.limits.FoxgloveLimits``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

from .access import AccessPolicy

if TYPE_CHECKING:
    from ..auth import Authenticator

__all__ = ["HOLD_BUDGET_S", "ClientRules", "MiB"]

MiB: Final = 1024 * 1024

HOLD_BUDGET_S: Final = 5.0
"""Default ``ClientRules.hold_budget_s``: seconds a publisher (or caller) may be held
back by the congested connections it fills, in all, regaining a tenth of a second a
second (docs/limits.md, input backpressure).

Long enough for a subscriber that reads to take a burst whole (B19: 200,000
messages, the publisher held about half of the time), short against a stream
a subscriber cannot keep up with: after it, that subscriber loses its own
oldest messages and the publisher and every other subscriber go at full rate.
"""


@dataclass(frozen=True)
class ClientRules:
    """The per-client rules of every protocol (docs/limits.md lists each cap).

    Attributes:
        send_buffer_limit: bytes of outgoing frames kept queued before the oldest
            topic messages are dropped (D24, ``--send-buffer-limit``); each frame
            counts its payload plus ``outbox.FRAME_OVERHEAD_BYTES``, so the
            limit bounds the memory a stalled peer holds.
        send_timeout_s: seconds a connection may stay over ``send_buffer_limit``
            without taking any frame before it is closed (D24, ``--send-timeout``).
        hold_budget_s: seconds this connection, as a reader, may be held back
            by the congested outboxes it fills (input backpressure,
            ``--hold-budget``), in all, whoever it waits for, regaining it
            slowly; a connection it was waiting for when it ran out is slow and
            loses its own oldest topic messages (D24) instead (docs/limits.md).
        access: the access rules (``--topics-glob`` and friends).
        authenticator: when set, a client must authenticate: with rosbridge's
            first op, an ``auth`` it admits (D23), or with a token in the
            handshake's URL (D33).
        call_timeout_s: seconds a service call without its own timeout waits
            before it fails (D16, ``--call-timeout``); None waits for ever.
        max_subscriptions: topics one connection may subscribe to at once
            (``--max-subscriptions``); the next subscription is refused.
        max_advertisements: topics, services and actions one connection may
            advertise at once, together (``--max-advertisements``).
        max_pending_calls: service calls of one connection waiting for their
            reply (``--max-pending-calls``); the next is answered as failed.
        idle_timeout_s: seconds after which a connection whose peer sent nothing and
            that holds nothing (``SessionBase.holds_anything``) is closed
            (``idle.IdleWatch``); None: never. A ``GraphServer`` sets it from
            ``ServerConfig.idle_timeout_s`` for WebSocket and TCP connections
            (``--idle-timeout``).
        qos_lifespan_s: the lifespan of a subscription that asks none (a rosbridge
            ``subscribe`` whose ``qos`` gives none, a Foxglove client's, an HTTP
            event stream's, an MCP tool's), seconds: no message older than this is
            sent to it (``SessionBase.message_end``; ``--qos-lifespan``, D63; inf:
            none, as rosbridge_suite).
    """

    send_buffer_limit: int = 16 * MiB
    send_timeout_s: float = 30.0
    hold_budget_s: float = HOLD_BUDGET_S
    access: AccessPolicy = field(default_factory=AccessPolicy)
    authenticator: Authenticator | None = None
    call_timeout_s: float | None = 30.0
    max_subscriptions: int = 1000
    max_advertisements: int = 1000
    max_pending_calls: int = 1000
    idle_timeout_s: float | None = None
    qos_lifespan_s: float = math.inf
