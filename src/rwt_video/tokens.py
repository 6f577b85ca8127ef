"""Short-lived tokens that open the video server's streams when the server asks for auth.

With ``--auth-secret-file`` every rosbridge connection must send an admitted
``auth`` op first (D23), but an ``<img>`` or a ``<video>`` cannot send one: it
only fetches a URL. So an authenticated connection asks for a token, calling
the service ``/rwt/video_token`` (``std_srvs/srv/Trigger``; the token is the
response's ``message``), and puts it in the stream URL (``?token=...``); the
video server answers only requests that carry a live token (docs/video.md, D32).
The same tokens open MCP sessions and WebRTC offers (``Authorization: Bearer``).

A token is signed, not stored: its expiry and 64 random bits (``secrets``),
followed by an HMAC-SHA256 of both under a key made when the ``VideoTokens`` is
(256 random bits, never sent). ``valid`` checks the signature with
``hmac.compare_digest`` (the time a check takes says nothing about how close a
forgery was) and the expiry. Nothing is kept per token, so no client can push
another's token out by asking for many (there is no store to fill, D32); a
token opens streams until it expires, ``lifetime_s`` after it was issued, and
a stream already open goes on after that (as a WebSocket connection does after
its ``auth`` op's ``end``).
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import secrets
import struct
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalService

__all__ = [
    "TOKEN_CHARS",
    "TOKEN_SERVICE",
    "TOKEN_SERVICE_TYPE",
    "VideoTokens",
    "install_token_service",
]

TOKEN_SERVICE = "/rwt/video_token"
"""The service an authenticated connection calls for a video token."""

TOKEN_SERVICE_TYPE = "std_srvs/srv/Trigger"
"""Its type: ``success`` true and the token as ``message``."""

_LABEL = b"rwt-video-token-1"  # what the key signs, so it signs nothing else
_EXPIRY = struct.Struct(">q")  # the expiry, microseconds of the tokens' clock
_NONCE_BYTES = 8
_MAC_BYTES = hashlib.sha256().digest_size
_TOKEN_BYTES = _EXPIRY.size + _NONCE_BYTES + _MAC_BYTES
TOKEN_CHARS = 64
"""Characters of a token: URL-safe base64 (no padding) of its 48 bytes."""


class VideoTokens:
    """Video tokens: ``issue()`` makes one, ``valid(token)`` checks one; none is stored.

    Args:
        lifetime_s: how long a token opens streams, seconds (60).
        clock: monotonic seconds (``time.monotonic``; a test may pass its own).

    Raises:
        ValueError: ``lifetime_s`` is not positive.
    """

    def __init__(
        self, lifetime_s: float = 60.0, clock: Callable[[], float] = time.monotonic
    ) -> None:
        if lifetime_s <= 0:
            raise ValueError("lifetime_s must be positive")
        self.lifetime_s = lifetime_s
        self._clock = clock
        self._key = secrets.token_bytes(32)

    def issue(self) -> str:
        """A new token: ``TOKEN_CHARS`` URL-safe characters, live ``lifetime_s``."""
        expiry_us = round((self._clock() + self.lifetime_s) * 1e6)
        body = _EXPIRY.pack(expiry_us) + secrets.token_bytes(_NONCE_BYTES)
        return base64.urlsafe_b64encode(body + self._sign(body)).decode().rstrip("=")

    def valid(self, token: str) -> bool:
        """Whether ``token`` was issued here and has not expired.

        The signature is compared in constant time before the expiry is read, so a
        forged token learns nothing from how long the check took.
        """
        if len(token) != TOKEN_CHARS or not token.isascii():
            return False
        try:
            raw = base64.urlsafe_b64decode(token + "=" * (-len(token) % 4))
        except (binascii.Error, ValueError):
            return False
        if len(raw) != _TOKEN_BYTES:
            return False
        body, mac = raw[:-_MAC_BYTES], raw[-_MAC_BYTES:]
        if not hmac.compare_digest(mac, self._sign(body)):
            return False
        (expiry_us,) = _EXPIRY.unpack_from(body)
        return bool(self._clock() * 1e6 < expiry_us)

    def _sign(self, body: bytes) -> bytes:
        return hmac.digest(self._key, _LABEL + body, "sha256")


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
