"""The error tree of rwt.

``RwtError`` is the root. Errors that a peer caused (``RemoteProtocolError``, and
graph errors such as an unknown type) carry the status level they are reported
at; the session turns them into ``status`` frames in one place (PROTOCOL-DECISIONS
D1). ``LocalProtocolError`` means embedding code misused the API and is raised to
it. Any other exception escaping rwt is a bug.
"""

from __future__ import annotations

from .levels import StatusLevel

__all__ = [
    "FieldError",
    "GraphError",
    "LimitError",
    "LocalProtocolError",
    "ProtocolError",
    "RemoteProtocolError",
    "RwtError",
    "TransportError",
]


class RwtError(Exception):
    """Root of every error rwt raises on purpose.

    Args:
        message: lowercase text without a trailing period, shaped
            ``<what> (expected X, got Y) at <path>`` where that applies.
        level: the status level the error is reported at when it reaches a client.
    """

    def __init__(self, message: str, *, level: StatusLevel = StatusLevel.ERROR) -> None:
        super().__init__(message)
        self.message = message
        self.level = level


class ProtocolError(RwtError):
    """A violation of the rosbridge protocol."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something invalid; it becomes a ``status`` frame (D1)."""


class LimitError(RemoteProtocolError):
    """The op would take this connection over one of its caps (docs/limits.md)."""


class LocalProtocolError(ProtocolError):
    """Embedding code misused the API (for example sent an op in the wrong role)."""


class GraphError(RwtError):
    """The graph refused an operation: unknown type, type conflict, unknown topic..."""


class FieldError(GraphError):
    """A message value does not fit its type (PROTOCOL-DECISIONS D9).

    Args:
        path: JSON path of the offending value, ``$.msg.pose.position.x``.
        problem: what is wrong, ``expected float64, got str``.
    """

    def __init__(self, path: str, problem: str) -> None:
        super().__init__(f"{problem} at {path}")
        self.path = path
        self.problem = problem


class TransportError(RwtError):
    """A transport failed; mapped from anyio/websockets errors at the boundary."""
