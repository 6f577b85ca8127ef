"""Option definitions shared by several commands (``rwt serve``, ``rwt play``)."""

from __future__ import annotations

from enum import StrEnum
from typing import Any

from rwt_protocol.distribution import install_hint
from rwt_protocol.levels import StatusLevel

__all__ = [
    "MCP_EXTRA",
    "MIB",
    "PORT_RANGE",
    "UVLOOP_EXTRA",
    "VIDEO_PORT",
    "WEBRTC_EXTRA",
    "LevelName",
    "LogLevel",
]

MIB = 1024 * 1024
PORT_RANGE: dict[str, Any] = {"min": 0, "max": 65535}
VIDEO_PORT = 8080
UVLOOP_EXTRA = install_hint("uvloop")
WEBRTC_EXTRA = install_hint("webrtc")
MCP_EXTRA = install_hint("mcp")

# typer offers an enum's values as choices: the status levels' wire spellings, made
# from StatusLevel itself so the two cannot differ (Dialect is a StrEnum already)
LevelName = StrEnum("LevelName", [(level.name, level.wire) for level in StatusLevel])  # type: ignore[misc]


class LogLevel(StrEnum):
    """Log levels as the CLI accepts them."""

    DEBUG = "debug"
    INFO = "info"
    WARNING = "warning"
    ERROR = "error"
