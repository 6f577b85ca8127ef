"""Which HTTP endpoint on the WebSocket port a request is for, from its first bytes.

The WebSocket listener reads the start of a connection and offers it to each HTTP
endpoint (WebRTC signalling, MCP) before the WebSocket handshake takes it
(docs/architecture.md, "HTTP endpoints on the WebSocket port").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

__all__ = ["claims_path"]


def claims_path(
    head: bytes,
    methods: Sequence[bytes],
    path: str,
    accepts: Callable[[bytes, bytes], bool],
) -> bool | None:
    """Whether the request starting with ``head`` is one of ``methods`` on ``path``.

    Args:
        head: the first bytes the client sent (a request line's start).
        methods: the HTTP methods the endpoint answers, such as ``b"POST"``.
        path: the endpoint's path, such as ``/webrtc``.
        accepts: ``accepts(method, byte)`` says whether the byte after the path
            (``b" "``, ``b"/"``, ``b"?"``...) still names the endpoint.

    Returns:
        True or False; None while ``head`` is too short to tell.
    """
    target = path.encode()
    for method in methods:
        prefix = method + b" " + target
        if len(head) <= len(prefix):
            if prefix.startswith(head):
                return None
            continue
        if head.startswith(prefix):
            return accepts(method, head[len(prefix) : len(prefix) + 1])
    return False
