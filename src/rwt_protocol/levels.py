"""Status levels of the rosbridge protocol and the filter they define.

Spec 3.2: four levels, ``none`` < ``error`` < ``warning`` < ``info``; a client at
level L receives status messages of level L and every level below it.
D2 makes ``error`` the default.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Literal

__all__ = ["StatusLevel", "WireLevel"]

WireLevel = Literal["none", "error", "warning", "info"]
"""A level as the spec spells it (``set_level``'s ``level``; a ``status`` has all but ``none``)."""


class StatusLevel(IntEnum):
    """How verbose a connection's status messages are (spec 3.2).

    The integer order is the nesting order: a status message of level ``m``
    reaches a connection at level ``c`` when ``0 < m <= c``.
    """

    NONE = 0
    ERROR = 1
    WARNING = 2
    INFO = 3

    @property
    def wire(self) -> WireLevel:
        """The level as the spec spells it (``"warning"``)."""
        return _WIRE[self]

    @classmethod
    def from_wire(cls, text: str) -> StatusLevel:
        """Parse a wire spelling.

        Raises:
            ConfigError: ``text`` is not one of ``none``, ``error``, ``warning``, ``info``.
        """
        try:
            return cls[text.upper()]
        except KeyError:
            from .errors import ConfigError  # noqa: PLC0415 - errors.py imports this module

            raise ConfigError(f"unknown status level {text!r}") from None

    def admits(self, level: StatusLevel) -> bool:
        """Whether a connection at this level receives a status of ``level``."""
        return StatusLevel.NONE < level <= self


_WIRE: dict[StatusLevel, WireLevel] = {
    StatusLevel.NONE: "none",
    StatusLevel.ERROR: "error",
    StatusLevel.WARNING: "warning",
    StatusLevel.INFO: "info",
}
