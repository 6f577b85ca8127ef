"""Settings of the MCP endpoint on the WebSocket port (``rwt serve --mcp``, docs/mcp.md).

Apart from ``mcp_http`` so that the server's configuration names them without
loading the MCP SDK (the ``mcp`` extra), which only ``--mcp`` needs. What bounds
an MCP session as a client (its slots, its host's share, ``--idle-timeout``) is
the server's own configuration (D40).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["MCP_PATH", "McpOptions"]

MCP_PATH = "/mcp"
"""The MCP endpoint (Streamable HTTP): every request of an MCP client goes here."""


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
    """

    read_only: bool = False
    bearer_token: Callable[[str], bool] | None = None
