"""The STUN and TURN servers of ``rwt serve --webrtc --ice-server`` (docs/webrtc.md, "Through NAT").

An ICE server is given as one URL, the form of RFC 7064 (``stun:``) and RFC
7065 (``turn:``, ``turns:``) with TURN's long-term credentials in front of the
host, as ``USER:PASS@`` (percent-encoded where they hold ``:``, ``@`` or ``%``).
What aiortc can use is checked here, so a URL aiortc would skip without a word
is refused with its reason instead:

- ``stun:HOST[:PORT]`` (3478): a server-reflexive candidate, the address the
  NAT gives the server's socket. No credentials, no ``?transport`` (RFC 7064),
  no ``stuns:`` (aiortc has no STUN over TLS).
- ``turn:USER:PASS@HOST[:PORT][?transport=udp|tcp]`` (3478, UDP) and
  ``turns:USER:PASS@HOST[:PORT]`` (5349, TLS over TCP): a relayed candidate, an
  address on the TURN server that forwards to the server.
- a host name or an IPv4 address (aiortc's URL syntax has no IPv6 literal);
- at most one STUN and one TURN server (``turn:`` or ``turns:``): aiortc's ICE
  agent (aioice) takes one of each and would ignore the others.

No module here imports aiortc: the CLI checks the URLs without it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING
from urllib.parse import unquote

if TYPE_CHECKING:
    from collections.abc import Sequence

__all__ = ["ICE_SERVERS_PER_KIND", "IceServer", "parse_ice_server", "parse_ice_servers"]

ICE_SERVERS_PER_KIND = 1
"""STUN servers, and TURN servers, ``--ice-server`` takes: aiortc's ICE agent (aioice) uses
one of each and ignores the others, so a second is refused rather than left unused."""

_DEFAULT_PORT = {"stun": 3478, "turn": 3478, "turns": 5349}
_TRANSPORTS = {"turn": ("udp", "tcp"), "turns": ("tcp",)}
_HOST = re.compile(r"^[A-Za-z0-9]([A-Za-z0-9.-]{0,251}[A-Za-z0-9])?$")
_FORMS = "stun:HOST[:PORT] or turn:USER:PASS@HOST[:PORT][?transport=udp|tcp] or turns:..."


@dataclass(frozen=True, slots=True)
class IceServer:
    """One STUN or TURN server, as aiortc's ``RTCIceServer`` takes it.

    Attributes:
        url: the URL without credentials (``turn:turn.example.org:3478?transport=tcp``).
        username: TURN's user name; None for STUN.
        credential: TURN's password; None for STUN.
    """

    url: str
    username: str | None = None
    credential: str | None = None

    @property
    def kind(self) -> str:
        """``stun`` or ``turn`` (``turns`` too): aiortc uses one server of each."""
        return "stun" if self.url.startswith("stun:") else "turn"

    def __repr__(self) -> str:  # the password stays out of logs and tracebacks
        return f"IceServer({self.url!r}, username={self.username!r})"


def parse_ice_server(text: str) -> IceServer:
    """The ICE server of one ``--ice-server`` URL.

    Args:
        text: ``stun:HOST[:PORT]``, ``turn:USER:PASS@HOST[:PORT][?transport=udp|tcp]``
            or ``turns:USER:PASS@HOST[:PORT]`` (RFC 7064, RFC 7065; credentials
            percent-encoded).

    Raises:
        ValueError: the URL is not of these forms, or aiortc could not use it; the
            message says what is wrong.
    """
    scheme, colon, rest = text.strip().partition(":")
    scheme = scheme.lower()
    whole = repr(text) if "@" not in text else "the URL"  # no password in an error
    if not colon or scheme not in _DEFAULT_PORT:
        if scheme == "stuns":
            raise ValueError(f"{whole}: aiortc has no STUN over TLS (stuns:); use stun:")
        raise ValueError(f"{whole} is not {_FORMS}")
    rest, question, query = rest.partition("?")
    userinfo, at, hostport = rest.rpartition("@")
    shown = f"{scheme}:***@{hostport}" if at else f"{scheme}:{hostport}"
    name = shown + (f"?{query}" if question else "")  # what an error shows: no password
    username, credential = _credentials(scheme, userinfo if at else None, name)
    host, port = _host_port(scheme, hostport, name)
    transport = _transport(scheme, query if question else None, name)
    url = f"{scheme}:{host}:{port}" + (f"?transport={transport}" if transport else "")
    return IceServer(url, username, credential)


def _credentials(scheme: str, userinfo: str | None, name: str) -> tuple[str | None, str | None]:
    """TURN's ``USER:PASS`` (percent-decoded); none for STUN."""
    if scheme == "stun":
        if userinfo is not None:
            raise ValueError(f"{name}: a STUN server takes no USER:PASS@")
        return None, None
    user, colon, password = (userinfo or "").partition(":")
    if userinfo is None or not colon or not user:
        raise ValueError(f"{name}: a TURN server needs its credentials: {scheme}:USER:PASS@HOST")
    return unquote(user), unquote(password)


def _host_port(scheme: str, hostport: str, name: str) -> tuple[str, int]:
    """The host name or IPv4 address and the port (the scheme's default without one)."""
    if hostport.startswith("["):
        raise ValueError(f"{name}: aiortc takes no IPv6 address here: use a host name")
    host, colon, port_text = hostport.partition(":")
    if not _HOST.match(host):
        raise ValueError(f"{name}: {host!r} is not a host name or IPv4 address")
    if not colon:
        return host, _DEFAULT_PORT[scheme]
    if not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise ValueError(f"{name}: the port {port_text!r} is not a number from 1 to 65535")
    return host, int(port_text)


def _transport(scheme: str, query: str | None, name: str) -> str | None:
    """TURN's ``?transport=`` (None: the scheme's default); STUN takes none (RFC 7064)."""
    if query is None:
        return None
    if scheme == "stun":
        raise ValueError(f"{name}: a stun: URL takes no ?transport (RFC 7064)")
    key, _, value = query.partition("=")
    allowed = _TRANSPORTS[scheme]
    if key != "transport" or value.lower() not in allowed:
        raise ValueError(f"{name}: {scheme}: takes ?transport={'|'.join(allowed)} only")
    return value.lower()


def parse_ice_servers(urls: Sequence[str]) -> tuple[IceServer, ...]:
    """The ICE servers of the ``--ice-server`` URLs, at most one STUN and one TURN.

    Raises:
        ValueError: a URL ``parse_ice_server`` refuses, or a second STUN or TURN
            server (aiortc's ICE agent takes one of each).
    """
    servers = tuple(parse_ice_server(url) for url in urls)
    for kind in ("stun", "turn"):
        if sum(server.kind == kind for server in servers) > ICE_SERVERS_PER_KIND:
            raise ValueError(
                f"more than one {kind.upper()} server: aiortc uses one STUN and one TURN server"
            )
    return servers
