"""Settings of the MCP endpoint on the WebSocket port (``rwt serve --mcp``, docs/mcp.md).

Apart from ``mcp_http`` so that the server's configuration names them without
loading the MCP SDK (the ``mcp`` extra), which only ``--mcp`` needs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["MCP_PATH", "MCP_SESSION_IDLE_S", "McpOptions"]

MCP_PATH = "/mcp"
"""The MCP endpoint (Streamable HTTP): every request of an MCP client goes here."""

MCP_SESSION_IDLE_S = 600.0
"""Seconds an MCP session lives with no request in flight; then it ends (its id: 404)."""


@dataclass(frozen=True, slots=True)
class McpOptions:
    """Settings of ``rwt serve --mcp``.

    Attributes:
        read_only: refuse the tools that change the robot (``--mcp-read-only``;
            ``rwt_mcp.guard.WRITE_TOOLS``).
        bearer_token: with an authenticator (``--auth-secret-file``), checks the
            token of a new session's ``Authorization: Bearer`` header (the video
            tokens of ``/rwt/video_token``, ``rwt_video.VideoTokens.valid``);
            None: every new session gets 401.
        idle_s: seconds an MCP session lives without a request (``MCP_SESSION_IDLE_S``).
    """

    read_only: bool = False
    bearer_token: Callable[[str], bool] | None = None
    idle_s: float = MCP_SESSION_IDLE_S
