"""The errors of TF lookups and of storing transforms."""

from __future__ import annotations

from rwt_protocol.errors import GraphError

__all__ = ["DisconnectedFramesError", "ExtrapolationError", "TFError", "UnknownFrameError"]


class TFError(GraphError):
    """A transform could not be stored or looked up; the message says why."""


class UnknownFrameError(TFError):
    """A frame no transform names (neither as child nor as parent)."""


class DisconnectedFramesError(TFError):
    """Both frames exist but lie in different trees."""


class ExtrapolationError(TFError):
    """The lookup time is outside the history a link still holds."""
