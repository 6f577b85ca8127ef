"""What a session asks its transport to do besides sending frames."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

__all__ = ["CloseCode", "CloseConnection", "Command"]


class CloseCode(IntEnum):
    """Why a session closes its connection, as RFC 6455 close codes (other transports log them)."""

    NORMAL = 1000
    GOING_AWAY = 1001  # server shutdown
    INVALID_DATA = 1007  # a text message that is not UTF-8 (RFC 6455 section 8.1)
    POLICY_VIOLATION = 1008  # authentication failed, slow consumer
    MESSAGE_TOO_BIG = 1009
    INTERNAL_ERROR = 1011  # keepalive timeout
    TRY_AGAIN_LATER = 1013  # too many connections


@dataclass(frozen=True, slots=True)
class CloseConnection:
    """Command: close the connection (code per RFC 6455, reason for the peer and the log).

    ``abort`` means the peer is not reading: the transport need not wait for the
    close to be delivered before cutting the connection (D24).
    """

    code: CloseCode
    reason: str
    abort: bool = False


Command = CloseConnection
"""What a session asks its transport to do besides sending frames."""
