r"""UDP address validation: a peer proves it receives at its address before it is served.

UDP's source address is whatever the sender writes, so without a check a datagram
with a forged source could make the server stream to a victim (reflection and
amplification) or act inside another peer's session. As QUIC does, the server
answers an address it has not validated with one small datagram holding a token
(at most ``AMPLIFICATION`` times the bytes it received, so it is never an
amplifier), and creates a session only for a datagram that carries that token:
only a peer that receives at the address can know it. Every datagram of the
session then carries the same token, so a forged source cannot act inside it
even after the peer authenticated.

What a UDP client does (docs/limits.md, "UDP"):

1. Send any datagram of at least ``MIN_PROBE_BYTES`` bytes (pad JSON with
   spaces), e.g. its first op. It is not served; the answer is
   ``{"op":"status","level":"warning","msg":"udp: address validation","id":TOKEN}``.
   UDP may lose either datagram: without an answer within a second, send it again.
2. Send every datagram as ``TOKEN``, a newline (``\\n``), then the JSON or CBOR
   frame. Replies come as plain datagrams, as before.
3. If that challenge arrives again (the session was idle past
   ``--udp-idle-timeout`` and the token expired), take the new token and resend.
   A challenge whose ``msg`` is ``SESSION_CHALLENGE_TEXT`` says the server still
   holds a session for the address: a client that holds a token ignores it (a
   datagram without that token drew it, perhaps forged); only a client without
   one (restarted on the same port) takes its token, which replaces the session.

Tokens are an HMAC of the peer's address and a 30 s epoch under a key made at
start-up; one is accepted for a new session during its epoch and the next one.

With ``--auth-bind-connection`` (D31) the answer is two datagrams, the challenge
and the address's ``auth_challenge`` status (``auth_challenge``, another HMAC of
the address and the epoch): the client can sign it before its first op, so that
op can be its ``auth`` (``auth``). Both count towards ``AMPLIFICATION`` and
``CHALLENGE_BUDGET_BYTES``. Nothing is kept per unvalidated address but the bytes
sent to it this epoch.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import re
import secrets
import time
from typing import TYPE_CHECKING

from rwt_protocol.auth import AUTH_CHALLENGE_ID
from rwt_protocol.codecs.json import encode_op
from rwt_protocol.ops import Status

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = [
    "AMPLIFICATION",
    "CHALLENGE_TEXT",
    "MIN_PROBE_BYTES",
    "SESSION_CHALLENGE_TEXT",
    "AddressValidator",
    "split_token",
]

AMPLIFICATION = 3
"""The most bytes sent to an unvalidated address per byte received from it (QUIC's rule)."""

MIN_PROBE_BYTES = 72
"""A first datagram at least this long is always answered with a challenge: the longest
answer, a session challenge and the auth challenge, is 216 bytes, ``AMPLIFICATION`` times 72."""

CHALLENGE_TEXT = "udp: address validation"
"""The ``msg`` of the challenge status."""

SESSION_CHALLENGE_TEXT = "udp: address validation; this address has a session"
"""The ``msg`` of the challenge to an address the server holds a validated session for.

Anyone can draw it with a datagram forged from that address, so a client that holds
its session's token ignores it (its session goes on); taking its token would replace
the session, with its subscriptions and authentication (docs/limits.md, UDP)."""

EPOCH_S = 30.0
"""Seconds a token is issued for; it is accepted for a new session one epoch longer."""

CHALLENGE_BUDGET_BYTES = 1024
"""The most challenge bytes sent to one address per epoch, however many datagrams claim
it: a forged source draws at most this much towards its victim (docs/limits.md)."""

MAX_CHALLENGED = 4096
"""Addresses whose challenge bytes are counted per epoch; past them (a flood of forged
sources) no more challenges go out until the epoch ends."""

_TOKEN = re.compile(rb"[A-Za-z0-9_-]{22}")

Address = tuple[str, int]


class AddressValidator:
    """Issues and checks the tokens of one UDP socket, and its addresses' auth challenges.

    Args:
        key: the HMAC key; a fresh random one by default (tokens die with the server).
        clock: monotonic seconds.
    """

    def __init__(self, key: bytes | None = None, clock: Callable[[], float] = time.monotonic):
        self._key = key or secrets.token_bytes(32)
        self._clock = clock
        self._sent: dict[Address, int] = {}  # challenge bytes per address, this epoch
        self._sent_epoch = -1

    def token(self, address: Address, epoch: int | None = None) -> str:
        """The token of ``address`` for ``epoch`` (the current one by default): 22 characters."""
        if epoch is None:
            epoch = self._epoch()
        message = f"{address[0]}|{address[1]}|{epoch}".encode()
        digest = hmac.new(self._key, message, hashlib.sha256).digest()[:16]
        return base64.urlsafe_b64encode(digest).rstrip(b"=").decode("ascii")

    def valid(self, token: str, address: Address) -> bool:
        """Whether ``token`` was issued to ``address`` in this epoch or the one before."""
        epoch = self._epoch()
        return any(hmac.compare_digest(token, self.token(address, e)) for e in (epoch, epoch - 1))

    def auth_challenge(self, address: Address, epoch: int | None = None) -> str:
        """The ``auth_challenge`` of ``address`` for ``epoch`` (the current one by default).

        Returns:
            32 lowercase hex digits (128 bits, as ``rwt_protocol.auth.new_challenge``):
            an HMAC of the address and the epoch, so none is stored, and none can be
            told without the key.
        """
        if epoch is None:
            epoch = self._epoch()
        message = f"auth|{address[0]}|{address[1]}|{epoch}".encode()
        return hmac.new(self._key, message, hashlib.sha256).hexdigest()[:32]

    def auth_nonce(self, address: Address, rand: str) -> str:
        """The challenge a new session of ``address`` holds its ``auth`` op's ``rand`` to.

        Returns:
            ``rand`` when it is the address's challenge of this epoch or the one
            before (the token's lifetime); otherwise this epoch's, which ``rand``
            then fails.
        """
        epoch = self._epoch()
        for e in (epoch, epoch - 1):
            nonce = self.auth_challenge(address, e)
            if hmac.compare_digest(rand.encode("utf-8"), nonce.encode()):
                return nonce
        return self.auth_challenge(address, epoch)

    def auth_status(self, address: Address) -> bytes:
        """The ``auth_challenge`` status of ``address``, as the other transports send it (D31)."""
        nonce = self.auth_challenge(address)
        return encode_op(Status(level="info", msg=nonce, id=AUTH_CHALLENGE_ID))

    def challenge(
        self, address: Address, received: int, *, has_session: bool = False, auth: bool = False
    ) -> list[bytes]:
        """The datagrams answering ``received`` bytes from an unvalidated ``address``.

        Args:
            address: where the datagram claims to come from.
            received: its length, bytes.
            has_session: the address holds a validated session: the challenge says
                so (``SESSION_CHALLENGE_TEXT``), so that its client keeps its token.
            auth: the auth challenge of the address goes with it
                (``--auth-bind-connection``).

        Returns:
            The challenge status, then the ``auth_challenge`` status when ``auth``;
            nothing when they would be more than ``AMPLIFICATION`` times
            ``received`` (a datagram too short to answer), or would take
            ``address`` past ``CHALLENGE_BUDGET_BYTES`` this epoch, or
            ``MAX_CHALLENGED`` other addresses were answered this epoch.
        """
        text = SESSION_CHALLENGE_TEXT if has_session else CHALLENGE_TEXT
        replies = [encode_op(Status(level="warning", msg=text, id=self.token(address)))]
        if auth:
            replies.append(self.auth_status(address))
        size = sum(map(len, replies))
        if size > AMPLIFICATION * received:
            return []
        epoch = self._epoch()
        if epoch != self._sent_epoch:
            self._sent, self._sent_epoch = {}, epoch
        sent = self._sent.get(address)
        if sent is None and len(self._sent) >= MAX_CHALLENGED:
            return []
        if (sent or 0) + size > CHALLENGE_BUDGET_BYTES:
            return []
        self._sent[address] = (sent or 0) + size
        return replies

    def _epoch(self) -> int:
        return int(self._clock() // EPOCH_S)


def split_token(data: bytes) -> tuple[str, bytes] | None:
    r"""``(token, frame)`` of a datagram sent as ``TOKEN\nframe``, or None if it is not one."""
    token, newline, frame = data.partition(b"\n")
    if not newline or _TOKEN.fullmatch(token) is None:
        return None
    return token.decode("ascii"), frame
