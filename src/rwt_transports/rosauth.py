"""rosauth's MAC check as the server's authenticator (D23, D31, D33).

``rosauth_authenticator`` checks ``auth`` ops (and, with ``url_token``, URL tokens)
against the shared secret at the graph's wall time; ``url_authenticator`` gives a
server the check of its URL tokens from the one of its ``auth`` ops. Each refusal is
logged once per episode with its reason (``event=auth_rejected``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.auth import BOUND_MAC_LABEL, URL_MAC_LABEL, Authenticator, RosauthVerifier

if TYPE_CHECKING:
    from rwt_graph.clock import Clock
    from rwt_protocol.ops import Auth

__all__ = ["rosauth_authenticator", "url_authenticator"]

logger = logging.getLogger("rwt.server")
_episodes = EpisodeLog(logger)  # a peer can trigger these at will


def rosauth_authenticator(
    secret: str,
    clock: Clock,
    max_skew_s: float = 5.0,
    *,
    bind_connection: bool = False,
    url_token: bool = False,
) -> Authenticator:
    """The rosauth MAC check (D23) as an authenticator, reading wall time from ``clock``.

    Args:
        secret: the shared secret.
        clock: where the current wall time comes from (the graph's clock).
        max_skew_s: how far in the future ``t`` may be, seconds.
        bind_connection: check ``bound_mac`` instead of rosauth's MAC
            (``--auth-bind-connection``, D31); the sessions must then send a
            challenge (``SessionConfig(auth_challenge=True)``).
        url_token: check URL tokens (D33) rather than ``auth`` ops: with
            ``bind_connection``, the bound MAC under ``URL_MAC_LABEL``. A
            server makes the URL tokens' check from the ``auth`` ops' one itself.
    """
    label = URL_MAC_LABEL if url_token else BOUND_MAC_LABEL
    verifier = RosauthVerifier(secret, max_skew_s, bound=bind_connection, label=label)
    return _Rosauth(verifier, clock)


@dataclass(frozen=True)
class _Rosauth:
    """rosauth's check as an ``Authenticator``: ``(op, peer) -> admitted`` (D23, D31, D33).

    Attributes:
        verifier: the MAC and time window check.
        clock: the wall time's source.
    """

    verifier: RosauthVerifier
    clock: Clock

    def __call__(self, op: Auth, peer: str) -> bool:
        """Whether ``op`` is valid now; a refusal is logged (rate-limited) with its reason."""
        problem = self.verifier.problem(op, self.clock.wall())
        if problem is not None:
            _episodes.log(
                logging.WARNING,
                "auth_rejected",
                "event=auth_rejected peer=%s reason=%r",
                peer,
                problem,
            )
        return problem is None

    def for_url_tokens(self) -> _Rosauth:
        """The same check for URL tokens: with a bound MAC, the URL token's (D33)."""
        return replace(self, verifier=replace(self.verifier, label=URL_MAC_LABEL))


def url_authenticator(authenticator: Authenticator) -> Authenticator:
    """The authenticator of URL tokens for a server whose ``auth`` ops ``authenticator`` checks.

    rosauth's (``rosauth_authenticator``) checks URL tokens under their own MAC
    with ``--auth-bind-connection`` (``for_url_tokens``), so a token opens only
    what it was issued for; an embedding program's own callable decides both
    (it gets the op and the peer, docs/embedding.md).
    """
    if isinstance(authenticator, _Rosauth):
        return authenticator.for_url_tokens()
    return authenticator
