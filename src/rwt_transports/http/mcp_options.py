"""Settings of the MCP endpoint on the WebSocket port (``rwt serve --mcp``, docs/mcp.md).

Apart from ``mcp`` so that the server's configuration names them without
loading the MCP SDK (the ``mcp`` extra), which only ``--mcp`` needs: the registry
(``frontends_registry.MCP``) loads ``mcp`` only when MCP is on. What bounds an MCP
session as a connection of the server (its slots, its host's share, the per-client
caps, ``--idle-timeout``) is the server's own configuration (D40).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

    from .mcp_siblings import McpSiblings

__all__ = ["MCP_PATH", "METADATA_PATH", "McpOptions"]

MCP_PATH = "/mcp"
"""The MCP endpoint (Streamable HTTP): every request of an MCP client goes here."""
METADATA_PATH = "/.well-known/oauth-protected-resource"
"""The endpoint's OAuth 2.0 protected-resource metadata (RFC 9728 section 3; also
answered with ``MCP_PATH`` appended, the form of section 3.1 for the resource ``/mcp``)."""


@dataclass(frozen=True, slots=True)
class McpOptions:
    """Settings of ``rwt serve --mcp``.

    Attributes:
        read_only: refuse the tools that change the robot (``--mcp-read-only``;
            ``rwt_mcp.guard.WRITE_TOOLS``).
        bearer_token: with an authenticator (``--auth-secret-file``), checks the
            token of a new session's ``Authorization: Bearer`` header (the video
            tokens of ``/rwt/video_token``, ``rwt_video.VideoTokens.valid``);
            None: the server's (``ServerConfig.bearer_token``), and without one
            every new session gets 401.
        authorization_server: the issuer URL of the OAuth 2.1 authorization server
            the protected-resource metadata names (``--mcp-authorization-server``;
            ``METADATA_PATH``); None: the metadata names none (rwt issues no tokens
            but its video tokens).
        video_port: the video server's port (``--video``), on the host clients reach
            ``/mcp`` by, for the robot app's MJPEG fallback (``rwt_mcp.app``); None:
            none, or not known.
        siblings: this worker's place among the workers of ``--workers N``, whose
            sessions and tasks it reaches (``mcp_siblings``); None: not a worker.
    """

    read_only: bool = False
    bearer_token: Callable[[str], bool] | None = None
    authorization_server: str | None = None
    video_port: int | None = None
    siblings: McpSiblings | None = None
