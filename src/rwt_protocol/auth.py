"""rosauth authentication (ROS 1 edition 3.3.1, D23, REF §2.22).

A trusted web server gives the browser a MAC computed from a secret it shares
with the robot; the client sends it in the first op, ``auth``. The session
asks an ``Authenticator`` whether to admit the connection; ``RosauthVerifier``
is the standard one (rosauth's ``ros_mac_authentication``), and embedding code
may pass any callable instead (a token check, a user database...).

Nothing here reads a clock: the wall time is passed in.

rosauth's MAC is over the fields concatenated and names no connection, so a
captured ``auth`` op is accepted on any new connection until its ``end``, and a
digit moved from ``t`` into ``rand`` keeps it valid (docs/server.md,
authentication). rwt's opt-in connection binding (``--auth-bind-connection``,
PROTOCOL-DECISIONS D31) closes both: the server sends each connection a
challenge first (a ``status`` op with ``id`` ``auth_challenge`` whose ``msg`` is
a fresh nonce), the client's ``rand`` must be that nonce, and the MAC is
``bound_mac``: an HMAC-SHA512 over the fields one per line.

A client that cannot send an ``auth`` op (a Foxglove client: its protocol has
none, and its user can only type a URL) carries the same fields in its
WebSocket URL's query string (``auth_query``, ``auth_from_query``); the server
checks them with the same authenticator before it accepts the handshake.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import math
import secrets
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from urllib.parse import parse_qsl, urlencode

from .errors import ConfigError, RemoteProtocolError
from .ops import Auth

__all__ = [
    "AUTH_CHALLENGE_ID",
    "QUERY_FIELDS",
    "URL_MAC_LABEL",
    "Authenticator",
    "RosauthVerifier",
    "auth_from_query",
    "auth_query",
    "bound_mac",
    "new_challenge",
    "rosauth_mac",
    "rosauth_op",
]

AUTH_CHALLENGE_ID = "auth_challenge"
"""The ``id`` of the ``status`` op carrying a connection's challenge (D31)."""

QUERY_FIELDS = ("mac", "client", "dest", "rand", "t", "level", "end")
"""The query parameters of a URL token: the ``auth`` op's fields, named as there."""

#: The first line of the text ``bound_mac`` signs: names the scheme and its version.
BOUND_MAC_LABEL = "rwt-auth-bound-1"

#: The first line of a bound URL token's MAC (``bound_mac(..., label=URL_MAC_LABEL)``):
#: a token for a URL (a Foxglove client's, D33) is signed apart from an ``auth`` op, so
#: an op signed for one connection's challenge opens no URL, and a URL token no connection.
URL_MAC_LABEL = "rwt-auth-url-1"

Authenticator = Callable[[Auth, str], bool]
"""Decides an ``auth`` op: called with the op and the peer address (``"host:port"``).

Returns True to admit the connection. It runs on the event loop, so it must not
block; an exception it raises counts as a refusal (and is logged).
"""


def _seconds(value: float) -> str:
    """Whole seconds as rosauth hashes them (``ros::Time::sec`` of the value)."""
    return str(math.floor(value))


def rosauth_mac(
    secret: str, *, client: str, dest: str, rand: str, t: float, level: str, end: float
) -> str:
    """Compute the rosauth MAC: lowercase hex SHA-512 of the fields concatenated.

    Args:
        secret: the shared secret (the first line of the secret file).
        client: the client's address, as the trusted source wrote it.
        dest: the server's address, likewise.
        rand: the random string of the trusted source.
        t: issue time, seconds since the epoch; only whole seconds count.
        level: the user level string.
        end: expiry time, seconds since the epoch; only whole seconds count.

    Returns:
        128 lowercase hex digits: ``sha512(secret + client + dest + rand + t +
        level + end)`` with ``t`` and ``end`` as whole seconds, as rosauth does.
    """
    text = f"{secret}{client}{dest}{rand}{_seconds(t)}{level}{_seconds(end)}"
    return hashlib.sha512(text.encode("utf-8")).hexdigest()


def new_challenge() -> str:
    """A fresh connection challenge: 32 lowercase hex digits (128 random bits)."""
    return secrets.token_hex(16)


def bound_mac(
    secret: str,
    *,
    client: str,
    dest: str,
    rand: str,
    t: float,
    level: str,
    end: float,
    label: str = BOUND_MAC_LABEL,
) -> str:
    r"""Compute the connection-bound MAC of ``--auth-bind-connection`` (D31).

    Args:
        secret: the shared secret.
        client: the client's address, as the trusted source wrote it.
        dest: the server's address, likewise.
        rand: the connection's challenge (the ``msg`` of the server's
            ``auth_challenge`` status).
        t: issue time, seconds since the epoch; only whole seconds count.
        level: the user level string.
        end: expiry time, seconds since the epoch; only whole seconds count.
        label: the first line: ``BOUND_MAC_LABEL`` for an ``auth`` op,
            ``URL_MAC_LABEL`` for a URL token (D33).

    Returns:
        128 lowercase hex digits: HMAC-SHA512 keyed with ``secret`` (UTF-8) of
        ``"LABEL\nCLIENT\nDEST\nRAND\nT\nLEVEL\nEND"`` (UTF-8), ``T``
        and ``END`` as whole seconds in decimal: each field on its own line, so
        no two field lists sign the same text.

    Raises:
        ConfigError: a field holds a line break (it could not be told apart).
    """
    fields = [label, client, dest, rand, _seconds(t), level, _seconds(end)]
    if any("\n" in field or "\r" in field for field in fields):
        raise ConfigError("auth fields cannot hold line breaks")
    text = "\n".join(fields)
    return hmac.new(secret.encode("utf-8"), text.encode("utf-8"), hashlib.sha512).hexdigest()


def rosauth_op(
    secret: str, *, client: str, dest: str, rand: str, t: float, level: str, end: float
) -> Auth:
    """Build a signed ``auth`` op (ROS 1 spec 3.3.1, D23): the fields and their ``mac``.

    Args:
        secret: the shared secret.
        client: the client's address, as the trusted source wrote it.
        dest: the server's address, likewise.
        rand: the random string of the trusted source.
        t: issue time, seconds since the epoch.
        level: the user level string.
        end: expiry time, seconds since the epoch.

    Returns:
        The ``auth`` op, ready to send (``codecs.json.encode_op``).
    """
    mac = rosauth_mac(secret, client=client, dest=dest, rand=rand, t=t, level=level, end=end)
    return Auth(mac=mac, client=client, dest=dest, rand=rand, t=t, level=level, end=end)


@dataclass(frozen=True)
class RosauthVerifier:
    """Checks ``auth`` ops against a shared secret (``--auth-secret-file``, D23).

    Attributes:
        secret: the shared secret.
        max_skew_s: how far in the future ``t`` may be, in seconds, for clocks
            that are not quite in step (rosauth tolerates 5 s).
        bound: expect ``bound_mac`` instead of rosauth's MAC
            (``--auth-bind-connection``, D31); the session checks that ``rand``
            is the connection's challenge.
        label: the bound MAC's label: ``BOUND_MAC_LABEL`` for ``auth`` ops,
            ``URL_MAC_LABEL`` for URL tokens (D33).
    """

    secret: str = field(repr=False)
    max_skew_s: float = 5.0
    bound: bool = False
    label: str = BOUND_MAC_LABEL

    def problem(self, op: Auth, wall_now: float) -> str | None:
        """Say what is wrong with ``op`` at ``wall_now``; None when it is valid.

        Valid means: ``t - max_skew_s <= wall_now <= end`` (D23) and the MAC
        matches (compared in constant time).

        Args:
            op: the client's ``auth`` op.
            wall_now: the current time, seconds since the epoch.
        """
        if wall_now > op.end:
            return f"expired (end {op.end:.0f} is before now {wall_now:.0f})"
        if op.t - self.max_skew_s > wall_now:
            return f"not yet valid (t {op.t:.0f} is after now {wall_now:.0f})"
        mac = functools.partial(bound_mac, label=self.label) if self.bound else rosauth_mac
        try:
            expected = mac(
                self.secret,
                client=op.client,
                dest=op.dest,
                rand=op.rand,
                t=op.t,
                level=op.level,
                end=op.end,
            )
        except ValueError as exc:
            return str(exc)
        if not hmac.compare_digest(expected.encode(), op.mac.lower().encode("utf-8")):
            return "MAC does not match"
        return None

    @classmethod
    def from_file(cls, text: str, max_skew_s: float = 5.0) -> RosauthVerifier:
        """Make a verifier from a secret file's contents (its first line, as rosauth reads it).

        Raises:
            ConfigError: the first line is empty.
        """
        secret = text.splitlines()[0].strip() if text.strip() else ""
        if not secret:
            raise ConfigError("the secret file's first line is empty")
        return cls(secret, max_skew_s)


def auth_query(op: Auth) -> str:
    """The URL query string that carries ``op``'s fields (a Foxglove client's token).

    Args:
        op: a signed ``auth`` op (``rosauth_op``, or with ``bound_mac``'s MAC).

    Returns:
        ``mac=...&client=...&dest=...&rand=...&t=...&level=...&end=...``, percent-encoded,
        ``t`` and ``end`` as whole seconds; append it to the URL after ``?``.
    """
    values = op.model_dump()
    values["t"], values["end"] = _seconds(op.t), _seconds(op.end)
    return urlencode([(name, values[name]) for name in QUERY_FIELDS])


def auth_from_query(query: str) -> Auth | None:
    """Read a URL token: the ``auth`` op whose fields a URL's query string carries.

    Args:
        query: the part of the URL after ``?`` (may be empty; other parameters
            are allowed and ignored).

    Returns:
        The op, for the authenticator to decide; None when the query has no ``mac``
        (no token at all).

    Raises:
        RemoteProtocolError: a token that cannot be read: a field missing or given
            twice, ``t`` or ``end`` not a finite number, more than 32 parameters.
    """
    try:
        pairs = parse_qsl(query, keep_blank_values=True, max_num_fields=32)
    except ValueError as exc:  # more fields than that, or bad percent-encoding
        raise RemoteProtocolError(f"unreadable auth query: {exc}") from None
    fields: dict[str, str] = {}
    for name, value in pairs:
        if name in QUERY_FIELDS:
            if name in fields:
                raise RemoteProtocolError(f"auth query: {name} is given twice")
            fields[name] = value
    if "mac" not in fields:
        return None
    missing = [name for name in QUERY_FIELDS if name not in fields]
    if missing:
        raise RemoteProtocolError(f"auth query: {', '.join(missing)} missing")
    return Auth(
        mac=fields["mac"],
        client=fields["client"],
        dest=fields["dest"],
        rand=fields["rand"],
        t=_number(fields, "t"),
        level=fields["level"],
        end=_number(fields, "end"),
    )


def _number(fields: Mapping[str, str], name: str) -> float:
    """The field ``name`` as a finite number (RemoteProtocolError otherwise)."""
    try:
        value = float(fields[name])
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise RemoteProtocolError(f"auth query: {name} is not a number")
    return value
