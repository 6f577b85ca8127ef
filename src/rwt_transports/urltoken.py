"""Admitting a handshake by the token in its URL (``frontends.AuthMode.URL_TOKEN``, D33).

A client whose protocol has no ``auth`` op (a Foxglove client, whose user can only
type a URL) carries the ``auth`` op's fields in its URL's query string
(``rwt_protocol.auth.auth_query``). ``url_token_gate`` checks them with the
server's URL-token authenticator during the handshake and refuses the
connection (HTTP 401 without a token, 403 with a bad one) before any session.
With ``--auth-bind-connection`` that authenticator checks a MAC of its own
(``rwt_protocol.auth.URL_MAC_LABEL``), so an ``auth`` op signed for one rosbridge
connection's challenge is no URL token, and a URL token is no ``auth`` op: each
token opens only what it was issued for (docs/server.md).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, TypeAlias
from urllib.parse import urlsplit

from rwt_protocol.auth import auth_from_query
from rwt_protocol.errors import RemoteProtocolError

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.auth import Authenticator

__all__ = ["BAD_TOKEN", "NO_TOKEN", "TokenGate", "url_token_gate"]

logger = logging.getLogger("rwt.server")

NO_TOKEN = "authentication required: add the token to the URL (docs/foxglove.md)"
"""The reason of a handshake refused for want of a URL token (HTTP 401)."""

BAD_TOKEN = "authentication failed"
"""The reason of a handshake whose URL token was refused (HTTP 403)."""

TokenGate: TypeAlias = "Callable[[str, str], tuple[int, str] | None]"
"""Decides a handshake from its request path (with its query) and the peer address:
the HTTP status and reason to refuse it with, or None to accept it as authenticated."""


def url_token_gate(authenticator: Authenticator) -> TokenGate:
    """Admit handshakes whose URL carries a token ``authenticator`` admits.

    The token is the ``auth`` op's fields as query parameters (``mac``, ``client``,
    ``dest``, ``rand``, ``t``, ``level``, ``end``; ``rwt_protocol.auth.auth_query``),
    checked as an ``auth`` op is: the same time window, the URL token's MAC.

    Args:
        authenticator: the server's URL-token authenticator
            (``server.rosauth_authenticator(..., url_token=True)``, or embedding code's).

    Returns:
        The gate: given the request path and the peer, (401, ``NO_TOKEN``) for a
        URL without ``mac``, (403, reason) for an unreadable or refused token (the
        reason says only what the client sent wrong; the authenticator logs its
        own), None to accept.
    """

    def refusal(path: str, peer: str) -> tuple[int, str] | None:
        try:
            op = auth_from_query(urlsplit(path).query)
        except (RemoteProtocolError, ValueError) as exc:
            return 403, f"{BAD_TOKEN}: {exc}"
        if op is None:
            return 401, NO_TOKEN
        try:
            admitted = authenticator(op, peer)
        except Exception:  # embedding code's check failed: a refusal, logged
            logger.exception("event=authenticator_failed peer=%s", peer)
            admitted = False
        if not admitted:
            return 403, BAD_TOKEN
        logger.info("event=auth_ok peer=%s level=%s via=url", peer, op.level)
        return None

    return refusal
