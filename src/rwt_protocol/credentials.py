"""The ways a client proves who it is (``AuthMode``), and the one check each goes through.

With an authenticator (``rwt serve --auth-secret-file``) every way into the server asks
for a proof; which one is its front end's ``AuthMode`` (``rwt_transports.frontends``):

- ``OP``: rosbridge's ``auth`` op, first on the connection, carrying a rosauth MAC
  (D23; signed over the connection's challenge with ``--auth-bind-connection``, D31).
  Nothing is checked at entry: the session checks the op when it comes.
- ``URL_TOKEN``: the ``auth`` op's fields in the URL's query (``auth.auth_query``, D33),
  for a client whose user can only type a URL (Foxglove); checked at the handshake.
- ``BEARER``: ``Authorization: Bearer <token>`` (RFC 6750 2.1) carrying a live video
  token (``/rwt/video_token``, D32), on each HTTP request: WebRTC offers, MCP, the
  HTTP API.
- ``VIDEO_TOKEN``: the same token in the URL's ``token`` parameter, or as a bearer
  token, for what can only fetch a URL (an ``<img>``: the video server, D32).
- ``NONE``: nothing to prove (``GET /version``, D49).

``EntryAuth`` is the one check every entry goes through: given a mode and what the
client presented, the ``Refusal`` (its HTTP status and text, the same for a mode
wherever it is checked) or None. ``bearer`` is the one reading of a bearer token
(``video_token`` reads the query's first), and ``op_refusal`` the one check of an
``auth`` op, which the session's gate (``rwt_protocol.server.gates``) and the URL
token share.

No clock is read here: a refusal a peer can repeat is logged once per episode at the
caller's ``now``.
"""

from __future__ import annotations

import hmac
import logging
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING
from urllib.parse import parse_qsl

from .auth import auth_from_query
from .errors import RemoteProtocolError
from .ratelog import EpisodeLog

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

    from .auth import Authenticator
    from .ops import Auth

__all__ = [
    "BAD_TOKEN",
    "NO_TOKEN",
    "AuthMode",
    "EntryAuth",
    "Refusal",
    "bearer",
    "op_refusal",
    "video_token",
]

logger = logging.getLogger("rwt.server")
_episodes = EpisodeLog(logger)  # a peer triggers these at will: one line per episode

NO_TOKEN = "authentication required: add the token to the URL (docs/foxglove.md)"
"""The text of a handshake refused for want of a URL token (HTTP 401)."""

BAD_TOKEN = "authentication failed"
"""The text of a handshake whose URL token was refused (HTTP 403)."""


class AuthMode(Enum):
    """One way a client proves who it is when the server has an authenticator (module text)."""

    OP = "op"
    """With the protocol's first op (rosbridge's ``auth``, D23); the URL is not read."""
    URL_TOKEN = "url"
    """With the ``auth`` op's fields in the handshake's URL, checked before any session (D33)."""
    BEARER = "bearer"
    """With ``Authorization: Bearer <video token>`` on each request (D32)."""
    VIDEO_TOKEN = "video"
    """With a video token as ``?token=`` or a bearer token (the video server, D32)."""
    NONE = "none"
    """Nothing to prove: the answer names nothing secret (``/version``, D49)."""

    @property
    def at_entry(self) -> bool:
        """Whether the proof comes with the request (checked at entry), not in an op."""
        return self not in (AuthMode.OP, AuthMode.NONE)


@dataclass(frozen=True, slots=True)
class Refusal:
    """Why an entry is refused: the HTTP status and the text the client is told.

    Attributes:
        status: 401 when nothing was presented (and for a bad bearer token, RFC 6750
            3.1), 403 for a proof that was refused.
        text: what the client is told; it never repeats the token.
        why: what the server's log says besides (the authenticator's reason).
    """

    status: int
    text: str
    why: str = ""


_NEED_BEARER = (
    "a bearer token is needed: call /rwt/video_token for one and send it as"
    " Authorization: Bearer <token>"
)
_BAD_BEARER = "the bearer token is wrong or expired: call /rwt/video_token for a new one"
_NEED_VIDEO = "a video token is needed: call /rwt/video_token and add ?token="
_BAD_VIDEO = "the video token is wrong or expired"


def bearer(headers: Mapping[str, str]) -> str | None:
    """The token of ``Authorization: Bearer <token>`` (RFC 6750 2.1), or None.

    The one reading of a bearer token for every front end; ``headers`` has
    lower-case names.
    """
    scheme, _, token = headers.get("authorization", "").partition(" ")
    return token.strip() or None if scheme.lower() == "bearer" else None


def op_refusal(
    authenticator: Authenticator,
    op: Auth,
    peer: str,
    *,
    nonce: str | None = None,
    now: float,
) -> str | None:
    """Why ``op`` proves nothing (for the log), or None: the one check of an ``auth`` op.

    Args:
        authenticator: decides the op (rosauth's MAC, or embedding code's check).
        op: the ``auth`` op, sent first (``OP``) or read from a URL (``URL_TOKEN``).
        peer: the peer's address, for the authenticator.
        nonce: the connection's challenge its ``rand`` must be (D31); None: any.
        now: the caller's monotonic seconds, for the log of a failing authenticator.

    An exception the authenticator raises is a refusal, logged with its traceback
    once per episode.
    """
    if nonce is not None and not hmac.compare_digest(op.rand.encode(), nonce.encode()):
        return "rand is not this connection's auth_challenge"  # a captured op (D31)
    try:
        admitted = authenticator(op, peer)
    except Exception:
        _episodes.log(
            logging.ERROR,
            "authenticator_failed",
            "event=authenticator_failed peer=%s",
            peer,
            exc_info=True,
            now=now,
        )
        admitted = False
    return None if admitted else "refused by the authenticator"


@dataclass(frozen=True, slots=True)
class EntryAuth:
    """The one check of every way in (module text): a mode and what the client presented.

    Attributes:
        required: the server asks for proofs (it has an authenticator, or the video
            server has tokens); False admits every entry.
        ops: checks ``auth`` ops (``OP``) and, without ``url``, URL tokens.
        url: checks URL tokens (``URL_TOKEN``; with ``--auth-bind-connection`` a MAC
            of their own, D33); None: ``ops``.
        token: checks video tokens (``BEARER``, ``VIDEO_TOKEN``;
            ``rwt_video.VideoTokens.valid``); None: every token is refused.
    """

    required: bool = False
    ops: Authenticator | None = None
    url: Authenticator | None = None
    token: Callable[[str], bool] | None = None

    def check(
        self,
        mode: AuthMode,
        peer: str,
        *,
        headers: Mapping[str, str] | None = None,
        query: str = "",
        now: float,
    ) -> Refusal | None:
        """Why an entry of ``mode`` is refused, or None to admit it.

        Args:
            mode: how the entry's front end proves who its client is.
            peer: the peer's address.
            headers: the request's headers, lower-case names (``BEARER``, ``VIDEO_TOKEN``).
            query: the request's query string, after ``?`` (``URL_TOKEN``, ``VIDEO_TOKEN``).
            now: monotonic seconds, for the log.

        Returns:
            None when nothing is required, for ``OP`` (its session asks for the
            op) and ``NONE``, and for a valid proof; else the mode's ``Refusal``.
        """
        if not self.required or not mode.at_entry:
            return None
        if mode is AuthMode.URL_TOKEN:
            return self._url_token(peer, query, now)
        if mode is AuthMode.VIDEO_TOKEN:
            token = video_token(headers or {}, query)
            if token is None:
                return Refusal(401, _NEED_VIDEO)
            return None if self._valid(token) else Refusal(403, _BAD_VIDEO, "bad video token")
        token = bearer(headers or {})
        if token is None:
            return Refusal(401, _NEED_BEARER)
        return None if self._valid(token) else Refusal(401, _BAD_BEARER, "bad bearer token")

    def _valid(self, token: str) -> bool:
        return self.token is not None and self.token(token)

    def _url_token(self, peer: str, query: str, now: float) -> Refusal | None:
        """A URL token (D33): 401 without ``mac``, 403 unreadable or refused."""
        try:
            op = auth_from_query(query)
        except (RemoteProtocolError, ValueError) as exc:
            return Refusal(403, f"{BAD_TOKEN}: {exc}", "unreadable URL token")
        if op is None:
            return Refusal(401, NO_TOKEN)
        authenticator = self.url or self.ops
        why = "no authenticator" if authenticator is None else None
        if authenticator is not None:
            why = op_refusal(authenticator, op, peer, now=now)
        if why is not None:
            return Refusal(403, BAD_TOKEN, why)
        logger.info("event=auth_ok peer=%s level=%s via=url", peer, op.level)
        return None


def video_token(headers: Mapping[str, str], query: str) -> str | None:
    """A video token as ``VIDEO_TOKEN`` reads it: the query's ``token``, else the bearer's.

    The last ``token`` parameter counts (as a query read into a dict keeps it); an
    empty one is none.
    """
    try:
        pairs = parse_qsl(query, keep_blank_values=True)
    except ValueError:  # bad percent-encoding
        pairs = []
    tokens = [value for name, value in pairs if name == "token"]
    return (tokens[-1] if tokens else None) or bearer(headers)
