"""Short-lived tokens that open the video server's streams when the server asks for auth.

With ``--auth-secret-file`` every rosbridge connection must send an admitted
``auth`` op first (D23), but an ``<img>`` or a ``<video>`` cannot send one: it
only fetches a URL. So an authenticated connection asks for a token, calling
the service ``/rwt/video_token`` (``std_srvs/srv/Trigger``; the token is the
response's ``message``), and puts it in the stream URL (``?token=...``); the
video server answers only requests that carry a live token (docs/video.md, D32).

Tokens are 256 random bits (``secrets``), live ``lifetime_s`` seconds, at most
``max_tokens`` at once (the oldest goes first), and are compared with
``hmac.compare_digest`` against every live one, so the time a check takes says
nothing about how close a guess was. A token may open several streams until it
expires; a stream already open goes on after its token expires (as a
WebSocket connection does after its ``auth`` op's ``end``).
"""

from __future__ import annotations

import hmac
import secrets
import time
from collections import deque
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalService

__all__ = ["TOKEN_SERVICE", "TOKEN_SERVICE_TYPE", "VideoTokens", "install_token_service"]

TOKEN_SERVICE = "/rwt/video_token"
"""The service an authenticated connection calls for a video token."""

TOKEN_SERVICE_TYPE = "std_srvs/srv/Trigger"
"""Its type: ``success`` true and the token as ``message``."""


class VideoTokens:
    """The live video tokens: ``issue()`` makes one, ``valid(token)`` checks one.

    Args:
        lifetime_s: how long a token opens streams, seconds (60).
        max_tokens: the most live tokens; issuing one more drops the oldest (256).
        clock: monotonic seconds (``time.monotonic``; a test may pass its own).

    Raises:
        ValueError: ``lifetime_s`` or ``max_tokens`` is not positive.
    """

    def __init__(
        self,
        lifetime_s: float = 60.0,
        max_tokens: int = 256,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if lifetime_s <= 0 or max_tokens <= 0:
            raise ValueError("lifetime_s and max_tokens must be positive")
        self.lifetime_s = lifetime_s
        self.max_tokens = max_tokens
        self._clock = clock
        self._live: deque[tuple[float, bytes]] = deque()  # (expiry, token), oldest first

    def issue(self) -> str:
        """A new token: 43 URL-safe characters (256 random bits), live ``lifetime_s``."""
        self._expire()
        while len(self._live) >= self.max_tokens:
            self._live.popleft()
        token = secrets.token_urlsafe(32)
        self._live.append((self._clock() + self.lifetime_s, token.encode()))
        return token

    def valid(self, token: str) -> bool:
        """Whether ``token`` is a live token, in time independent of where a guess differs."""
        self._expire()
        given = token.encode("utf-8", "replace")
        found = False
        for _, live in self._live:  # every one, no early exit
            found |= hmac.compare_digest(given, live)
        return found

    def __len__(self) -> int:
        """The number of live tokens."""
        self._expire()
        return len(self._live)

    def _expire(self) -> None:
        now = self._clock()
        while self._live and self._live[0][0] <= now:
            self._live.popleft()


def install_token_service(graph: Graph, tokens: VideoTokens) -> LocalService:
    """Offer ``/rwt/video_token`` on ``graph``, answering each call with a new token.

    Only callers the server admitted reach it: with an authenticator, a rosbridge
    connection's ops are served only after its ``auth`` op (D23). No client can
    advertise a service of its own there: an in-process provider is not replaced (D15).

    Returns:
        The service; ``close()`` withdraws it.
    """
    return graph.create_service(
        TOKEN_SERVICE,
        TOKEN_SERVICE_TYPE,
        lambda _request: {"success": True, "message": tokens.issue()},
    )
